"""A small hand-built Tree (no generator) following treegen_cli/tree.py's contract exactly.

stem 0  trunk, level 0: 5 nodes straight up z = 0, 2, 4, 6, 8; tip radius 0 (pointed)
stem 1  split clone of the trunk at trunk node 2 (z = 4), tilted 30°; 3 nodes; capped tip
stem 2  level 1 on trunk segment 1 (z = 3), 4 nodes, straight, 60° down angle
stem 3  level 1 on trunk segment 2 (z = 5), 4 nodes, bending up at its node 2
stem 4  level 2 on stem 2, 3 nodes
stem 5  level 2 on stem 3, 2 nodes, radius 1 mm (a "thin" twig)
leaves  on stems 4 and 5 (and one on stem 3), random proper frames
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from treegen_cli.params import Params
from treegen_cli.tree import Tree


def _stem(base, frames, seg_len, z0, radii):
    """Nodes of a stem: straight segments, segment i leaves node i along frames[i] column 2."""
    frames = np.asarray(frames, dtype=np.float64)
    pos = [np.asarray(base, dtype=np.float64)]
    for f in frames[:-1]:
        pos.append(pos[-1] + seg_len * f[:, 2])
    n = len(frames)
    return np.array(pos), frames, np.asarray(radii, dtype=np.float64), z0 + seg_len * np.arange(n)


def synthetic_tree(leaf_shape: int = 0, lobes: int = 0, lobe_depth: float = 0.0, flare: float = 0.0) -> Tree:
    params = dataclasses.replace(
        Params(),
        name="synthetic",
        levels=3,
        leaf_shape=leaf_shape,
        lobes=lobes,
        lobe_depth=lobe_depth,
        flare=flare,
    )
    eye = np.eye(3)
    rx30 = Rotation.from_euler("x", 30, degrees=True).as_matrix()
    ry60 = Rotation.from_euler("y", 60, degrees=True).as_matrix()
    b1 = Rotation.from_euler("zy", [180, 60], degrees=True).as_matrix()
    b2 = Rotation.from_euler("zy", [180, 30], degrees=True).as_matrix()
    c = Rotation.from_euler("zy", [90, 45], degrees=True).as_matrix()

    stems = []  # (level, parent, parent_node, offset, length, radius, clone, nodes)
    trunk = _stem([0, 0, 0], [eye] * 5, 2.0, 0.0, [0.4, 0.3, 0.2, 0.1, 0.0])
    stems.append((0, -1, -1, 0.0, 8.0, 0.4, False, trunk))
    clone = _stem(trunk[0][2], [rx30] * 3, 2.0, 4.0, [0.2, 0.1, 0.05])
    stems.append((0, 0, 2, 4.0, 8.0, 0.4, True, clone))
    a = _stem([0, 0, 3], [ry60] * 4, 1.0, 0.0, [0.1, 0.07, 0.04, 0.0])
    stems.append((1, 0, 1, 3.0, 3.0, 0.1, False, a))
    b = _stem([0, 0, 5], [b1, b1, b2, b2], 1.0, 0.0, [0.08, 0.06, 0.03, 0.0])
    stems.append((1, 0, 2, 5.0, 3.0, 0.08, False, b))
    a_start = 5 + 3  # global index of stem 2's node 0
    b_start = a_start + 4
    c4 = _stem(a[0][1] + 0.5 * a[1][1][:, 2], [c] * 3, 0.4, 0.0, [0.03, 0.02, 0.0])
    stems.append((2, 2, a_start + 1, 1.5, 0.8, 0.03, False, c4))
    c5 = _stem(b[0][2], [c] * 2, 0.3, 0.0, [0.001, 0.0])
    stems.append((2, 3, b_start + 2, 2.0, 0.3, 0.001, False, c5))

    counts = np.array([len(st[7][0]) for st in stems], dtype=np.int32)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int32)
    assert starts[2] == a_start and starts[3] == b_start

    rng = np.random.default_rng(7)
    leaf_stem = np.array([4, 4, 4, 5, 5, 3], dtype=np.int32)
    leaf_local = np.array([0, 1, 1, 0, 0, 2])
    leaf_node = (starts[leaf_stem] + leaf_local).astype(np.int32)
    node_pos = np.concatenate([st[7][0] for st in stems])
    leaf_frame = Rotation.random(len(leaf_stem), random_state=rng).as_matrix()
    leaf_pos = node_pos[leaf_node] + 0.01 * rng.standard_normal((len(leaf_stem), 3))
    leaf_size = np.column_stack(
        [np.linspace(0.1, 0.2, len(leaf_stem)), np.linspace(0.05, 0.08, len(leaf_stem))]
    )

    return Tree(
        params=params,
        seed=0,
        scale=8.0,
        stem_level=np.array([st[0] for st in stems], dtype=np.int8),
        stem_parent=np.array([st[1] for st in stems], dtype=np.int32),
        stem_parent_node=np.array([st[2] for st in stems], dtype=np.int32),
        stem_offset=np.array([st[3] for st in stems]),
        stem_length=np.array([st[4] for st in stems]),
        stem_radius=np.array([st[5] for st in stems]),
        stem_clone=np.array([st[6] for st in stems]),
        stem_node_start=starts,
        stem_node_count=counts,
        node_stem=np.repeat(np.arange(len(stems), dtype=np.int32), counts),
        node_pos=node_pos,
        node_frame=np.concatenate([st[7][1] for st in stems]),
        node_radius=np.concatenate([st[7][2] for st in stems]),
        node_z=np.concatenate([st[7][3] for st in stems]),
        leaf_stem=leaf_stem,
        leaf_node=leaf_node,
        leaf_pos=leaf_pos,
        leaf_frame=leaf_frame,
        leaf_size=leaf_size,
    )


def trunk_only(lobes: int = 0, lobe_depth: float = 0.0, flare: float = 0.0) -> Tree:
    """Just the straight trunk of `synthetic_tree` (stem 0, no leaves): its axis is the Z axis."""
    t = synthetic_tree(lobes=lobes, lobe_depth=lobe_depth, flare=flare)
    n = int(t.stem_node_count[0])
    one = slice(0, 1)
    return Tree(
        params=t.params,
        seed=0,
        scale=t.scale,
        stem_level=t.stem_level[one],
        stem_parent=t.stem_parent[one],
        stem_parent_node=t.stem_parent_node[one],
        stem_offset=t.stem_offset[one],
        stem_length=t.stem_length[one],
        stem_radius=t.stem_radius[one],
        stem_clone=t.stem_clone[one],
        stem_node_start=t.stem_node_start[one],
        stem_node_count=t.stem_node_count[one],
        node_stem=t.node_stem[:n],
        node_pos=t.node_pos[:n],
        node_frame=t.node_frame[:n],
        node_radius=t.node_radius[:n],
        node_z=t.node_z[:n],
        leaf_stem=np.zeros(0, np.int32),
        leaf_node=np.zeros(0, np.int32),
        leaf_pos=np.zeros((0, 3)),
        leaf_frame=np.zeros((0, 3, 3)),
        leaf_size=np.zeros((0, 2)),
    )


def species_tree(name: str, seed: int = 0) -> Tree:
    """A bundled species grown by the generator."""
    from treegen_cli.generate import generate
    from treegen_cli.params import load_params

    path = Path(__file__).resolve().parent.parent / "species" / f"{name}.txt"
    return generate(load_params(path), seed=seed)
