"""A LOD's skeleton is LOD0's with joints removed (rig.build_rig's `among`): every LOD joint
has LOD0's name for its node, sits where LOD0's joint of that name sits, and hangs from its
nearest ancestor in LOD0 that the LOD keeps. Engines take a tree's LODs as one skeletal mesh
and match their bones to LOD0's by name (Unreal: a LOD's bones a subset of LOD0's); named
from its own pruned tree, the aspen's LOD1 had 41 of its 128 joints where LOD0's joints of
those names are not, up to 1.7 m off ("b6_1" at LOD0's "b6_2")."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from conftest import grown, species_path

from treegen_cli.api import resolve
from treegen_cli.exchange import export, export_parts, lod_file_paths
from treegen_cli.exchange.gltf_container import read_gltf
from treegen_cli.exchange.read_gltf import _node_world
from treegen_cli.params import load_params
from treegen_cli.pipeline import build_asset
from treegen_cli.prepare import split_lods

TOL = 1e-6  # metres
# the aspen (the README's example); the oak: 22 trunks (base splits: "trunkS_K" names) and a
# thousand clones; the desert bush: two trunks, 2,000 clones, LOD0's branches jointed at their
# bases only (76 of its LOD1's 128 names were not LOD0's)
SPECIES = ["quaking_aspen", "ca_black_oak", "desert_bush"]


@lru_cache(maxsize=None)
def _asset(name: str):
    """The species' LODs, no wind (the joints are chosen before it) and no textures."""
    job = resolve(dict(no_wind=True, no_textures=True, impostor=False))
    return build_asset(load_params(species_path(name)), 0, job.options, tree=grown(name))[0]


def _kept_ancestor(parent0: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """(J0,) each LOD0 joint's nearest proper ancestor among `kept` (−1: none), one pass per
    generation of joints skipped."""
    up = parent0.copy()
    while (climb := (up >= 0) & ~kept[np.maximum(up, 0)]).any():
        up = np.where(climb, parent0[np.maximum(up, 0)], up)
    return up


def _check_subset(names0, parent0, pos0, names, parent, pos, what) -> None:
    """`names` (with `parent`, world positions `pos`) is LOD0's skeleton with joints removed."""
    assert len(set(names)) == len(names), what
    index0 = {n: i for i, n in enumerate(names0)}
    missing = [n for n in names if n not in index0]
    assert not missing, (what, missing[:5])
    at = np.array([index0[n] for n in names], dtype=np.int64)
    off = np.linalg.norm(pos - pos0[at], axis=1)
    assert off.max(initial=0.0) <= TOL, (what, names[int(np.argmax(off))], off.max())
    kept = np.zeros(len(names0), dtype=bool)
    kept[at] = True
    want = _kept_ancestor(np.asarray(parent0, dtype=np.int64), kept)[at]
    got = np.where(parent >= 0, at[np.maximum(parent, 0)], -1)
    assert np.array_equal(got, want), (what, np.flatnonzero(got != want)[:5])


@pytest.mark.parametrize("species", SPECIES)
def test_lod_skeletons_are_lod0s_with_joints_removed(species):
    asset = _asset(species)
    assert len(asset.lods) > 2
    s0 = asset.lods[0].skeleton
    pos0 = np.asarray(s0.bind_world)[:, :3, 3]
    assert len(set(s0.names)) == len(s0.names)
    for k, lod in enumerate(asset.lods[1:], 1):
        s = lod.skeleton
        pos = np.asarray(s.bind_world)[:, :3, 3]
        _check_subset(s0.names, s0.parent, pos0, s.names, np.asarray(s.parent), pos, (species, k))
        assert len(s.names) < len(s0.names)  # the LOD's joint budget (--lod-joints) holds
        # the same bind pose, turned as LOD0's joint is (a coarsened node's frame follows its
        # new segment: up to 13° at LOD3), so LOD0's animation can drive the LOD's bones
        at = [s0.names.index(n) for n in s.names]
        turn = np.asarray(s.bind_world)[:, :3, :3] - np.asarray(s0.bind_world)[at, :3, :3]
        assert np.abs(turn).max() <= 1e-12, (species, k, np.abs(turn).max())


def _skins(path):
    """Per skin of a written glTF: (joint names, parent skin joint or −1, rest world positions)."""
    gltf, _ = read_gltf(path)
    node_parent, world = _node_world(gltf)
    out = []
    for skin in gltf["skins"]:
        joints = np.asarray(skin["joints"], dtype=np.int64)
        slot = {int(j): i for i, j in enumerate(joints)}
        parent = np.array([slot.get(int(node_parent[j]), -1) for j in joints])
        out.append(([gltf["nodes"][j]["name"] for j in joints], parent, world[joints, :3, 3]))
    return out


@pytest.mark.parametrize("species", SPECIES[:2])
def test_written_lods_keep_lod0s_joint_names(species, tmp_path):
    """The same in the files: one GLB's skins (MSFT_lod), and the `--lod-files` parts an
    Unreal user imports as the LODs of one skeletal mesh."""
    asset = _asset(species)
    path = tmp_path / "tree.glb"
    export(asset, path)
    skins = _skins(path)
    assert len(skins) == len(asset.lods)
    for k, skin in enumerate(skins[1:], 1):
        _check_subset(*skins[0], *skin, ("glb", species, k))
    export_parts(split_lods(asset), path)
    parts = [_skins(p)[0] for p in lod_file_paths(path, len(asset.lods))]
    for k, part in enumerate(parts[1:], 1):
        _check_subset(*parts[0], *part, ("--lod-files", species, k))


def test_lod_trees_carry_lod0s_stem_and_node_indices():
    """prune_stems and coarsen_nodes (stub_stems) renumber stems and nodes; the LOD tree says
    which of LOD0's each one is (Tree.lod0_stems, lod0_nodes), through both in either order."""
    from treegen_cli.lod_leaves import prune_stems
    from treegen_cli.lod_nodes import coarsen_nodes

    tree0 = grown("quaking_aspen")
    keep = np.arange(tree0.n_stems) % 3 != 1
    for lod in (
        prune_stems(coarsen_nodes(tree0, 0.05), keep),
        coarsen_nodes(prune_stems(tree0, keep), 0.05),
    ):
        assert lod.n_nodes < tree0.n_nodes and lod.n_stems < tree0.n_stems
        stems, nodes = lod.lod0_stems, lod.lod0_nodes
        assert np.array_equal(lod.node_pos, tree0.node_pos[nodes])
        assert np.array_equal(tree0.node_stem[nodes], stems[lod.node_stem])
        assert np.array_equal(nodes[lod.stem_node_start], tree0.stem_node_start[stems])
        assert np.all(np.diff(nodes) > 0)
