"""LODs sway as LOD0 does (wind_lods.lod_angles): a LOD switch changes the tree's detail, not
its motion."""

from __future__ import annotations

from functools import lru_cache

import numpy as np
import pytest
from conftest import species_path
from lbs import skin_frames

from treegen_cli.api import resolve
from treegen_cli.drawable import from_asset
from treegen_cli.lod import LodOptions
from treegen_cli.params import load_params
from treegen_cli.pipeline import build_asset
from treegen_cli.silhouette import metres_per_pixel
from treegen_cli.wind import WindOptions

FRAMES = 24  # poses through the clip at which LODs are compared
MAX_JUMP_PX = 1.5  # the crown top's motion, LOD k against LOD k−1 at k's switch (was 2.6-5.7 px)
# each LOD's clip-mean lean against LOD0's (was 0.70-1.42 ×); LOD3's top fifth is other leaves
# than LOD0's, a few hundred metres away (the tupelo's leans 1.16 × there, 0.4 px from LOD2's)
LEAN_TOL = 0.2


@lru_cache(maxsize=None)
def _asset(name: str):
    job = resolve(dict(texture_size=128, wind_speed=6.0, duration=4.0, fps=15.0, impostor=False))
    asset, _ = build_asset(load_params(species_path(name)), 0, job.options)
    return asset


def _crown_top_motion(asset, k: int, t: np.ndarray) -> np.ndarray:
    """(T, 3) mean displacement from rest of LOD k's leaf vertices in the crown's top fifth."""
    d = from_asset(asset, k)
    leaves = [p for p in d.parts if p.double_sided and len(p.positions)]
    rest = np.concatenate([p.positions for p in leaves]).astype(np.float64)
    skin = d.pose(t)
    moved = np.concatenate([skin_frames(skin, p.positions, p.joints, p.weights) for p in leaves], axis=1)
    up = rest[:, 1]  # drawables are Y up
    top = up > np.quantile(up, 0.8)
    return (moved[:, top] - rest[top]).mean(axis=1)


@pytest.mark.parametrize("species", ["quaking_aspen", "black_tupelo"])
def test_a_lod_switch_keeps_the_motion(species):
    """At every switch the crown's top moves as it did in the LOD before (within MAX_JUMP_PX at
    the switch's size on screen, every pose through the clip), and every LOD leans downwind as
    far as LOD0 (within LEAN_TOL). Each LOD baked from its own thinned leaves and pruned rig, the
    aspen's LOD1 leaned 30 % less and its top jumped 5.7 px at the switch."""
    asset = _asset(species)
    t = np.linspace(0.0, from_asset(asset, 0).duration, FRAMES, endpoint=False)
    motion = [_crown_top_motion(asset, k, t) for k in range(len(asset.lods))]
    lean0 = motion[0].mean(axis=0)
    for k in range(1, len(asset.lods)):
        px = metres_per_pixel(asset.lods[k].distance, LodOptions())
        jump = np.linalg.norm(motion[k] - motion[k - 1], axis=1).max() / px
        assert jump <= MAX_JUMP_PX, (species, k, jump)
        lean = motion[k].mean(axis=0)
        assert np.linalg.norm(lean - lean0) <= LEAN_TOL * np.linalg.norm(lean0), (species, k, lean, lean0)


def test_chain_matrix_moves_points_as_their_joints_bend():
    """The fit's model (wind_lods._chain_matrix): a point carried by a joint moves by
    Σ θ_a × (p − pivot_a) over that joint and its ancestors; a point on a node blended between
    two joints moves by the blend of both chains' motion."""
    from types import SimpleNamespace

    from treegen_cli.wind_lods import _chain_matrix

    bind = np.tile(np.eye(4), (3, 1, 1))
    bind[1, :3, 3] = (0.0, 0.0, 1.0)  # child of the root, 1 m up
    bind[2, :3, 3] = (0.5, 0.0, 1.0)  # child of joint 1
    rig = SimpleNamespace(skeleton=SimpleNamespace(parent=np.array([-1, 0, 1]), bind_world=bind))
    theta = np.array([[0.01, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, -0.03]])
    pts = np.array([[0.0, 0.5, 2.0], [0.5, 0.2, 1.5]])
    carry = np.array([[1, 0], [2, 1]])
    weight = np.array([[1.0, 0.0], [0.25, 0.75]])
    d = (_chain_matrix(pts, carry, weight, rig) @ theta.reshape(-1)).reshape(2, 3)

    def moved(p, joint):
        out = np.zeros(3)
        while joint >= 0:
            out += np.cross(theta[joint], p - bind[joint, :3, 3])
            joint = [-1, 0, 1][joint]
        return out

    assert np.allclose(d[0], moved(pts[0], 1))
    assert np.allclose(d[1], 0.25 * moved(pts[1], 2) + 0.75 * moved(pts[1], 1))


def _own_turn_deg(clip, skeleton) -> np.ndarray:
    """Each joint's turn from its rest rotation at each key, degrees."""
    rest = np.asarray(skeleton.rest_rotation, dtype=np.float64)
    q = np.asarray(clip.rotations, dtype=np.float64)
    dot = np.abs(np.einsum("kjc,jc->kj", q, rest))
    return np.degrees(2.0 * np.arccos(np.clip(dot, 0.0, 1.0)))


def test_a_gale_bends_no_lod_past_the_bounds():
    """30 m/s: every LOD's joints stay within the wind's soft bound on a joint's own turn
    (WindOptions.max_angle_deg), as LOD0's do; the fitted bends of a LOD joint standing for a
    chain of LOD0's reached 42-43° on the aspen before they were bounded too."""
    job = resolve(dict(texture_size=128, wind_speed=30.0, duration=4.0, fps=15.0, impostor=False))
    asset, _ = build_asset(load_params(species_path("quaking_aspen")), 0, job.options)
    bound = WindOptions().max_angle_deg
    for k, lod in enumerate(asset.lods):
        turn = _own_turn_deg(lod.clips[0], lod.skeleton)
        assert turn.max() <= bound + 0.01, (k, turn.max())


def test_a_still_day_stays_still():
    """No wind: every LOD's clip holds its rest pose."""
    job = resolve(dict(texture_size=128, wind_speed=0.0, duration=2.0, fps=10.0, impostor=False))
    asset, _ = build_asset(load_params(species_path("rush")), 0, job.options)
    assert len(asset.lods) == 4
    for lod in asset.lods:
        assert _own_turn_deg(lod.clips[0], lod.skeleton).max() < 1e-3  # (acos near 1: float noise)
