"""A small hand-built Asset for writer tests (glTF, USD): known numbers, no generator needed.

Each LOD is a bent tube (a chain of joints, one ring of vertices per joint plus a tip ring)
with leaf quads on the last joints. LOD k has fewer joints, sides and leaves than LOD k-1.
The clip sways every non-root joint about generator X/Y with a few keys; LOD0's clip carries a
sparse key schedule (`Clip.keys`), lower LODs keep every key.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from treegen_cli.asset import Asset, Clip, Lod, Material, Primitive, Skeleton, Texture

SEGMENT = 2.5  # metres between joints along the chain
BEND_DEG = 15.0  # rest bend of every non-root joint about its local X


def _matrix(t: np.ndarray, q: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(q).as_matrix()
    m[:3, 3] = t
    return m


def chain_skeleton(n_joints: int) -> Skeleton:
    """A chain j0 → j1 → ... rooted at the origin, each joint SEGMENT above its parent, bent."""
    parent = np.arange(-1, n_joints - 1, dtype=np.int32)
    t = np.zeros((n_joints, 3))
    t[1:, 2] = SEGMENT
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n_joints, 1))
    q[1:] = Rotation.from_euler("x", BEND_DEG, degrees=True).as_quat()
    world = np.empty((n_joints, 4, 4))
    for j in range(n_joints):  # a handful of joints: the loop is fine
        local = _matrix(t[j], q[j])
        world[j] = local if parent[j] < 0 else world[parent[j]] @ local
    return Skeleton(
        names=[f"j{j}" for j in range(n_joints)],
        parent=parent,
        rest_translation=t,
        rest_rotation=q,
        bind_world=world,
    )


def _to_world(bind: np.ndarray, joint: np.ndarray, local: np.ndarray) -> np.ndarray:
    return np.einsum("vij,vj->vi", bind[joint, :3, :3], local) + bind[joint, :3, 3]


def bark(skel: Skeleton, sides: int, radius: float = 0.3) -> Primitive:
    """Tube: ring k sits on joint k (plus a tip ring SEGMENT above the last joint)."""
    J = len(skel.names)
    rings = J + 1
    ring_joint = np.minimum(np.arange(rings), J - 1)
    ring_z = np.where(np.arange(rings) < J, 0.0, SEGMENT)
    ring_r = radius * np.linspace(1.0, 0.3, rings)
    a = np.arange(sides) * (2 * np.pi / sides)
    ca, sa = np.cos(a), np.sin(a)
    local = np.stack(
        [ring_r[:, None] * ca, ring_r[:, None] * sa, np.broadcast_to(ring_z[:, None], (rings, sides))],
        axis=-1,
    ).reshape(-1, 3)
    nloc = np.tile(np.stack([ca, sa, np.zeros(sides)], axis=-1), (rings, 1))
    vj = np.repeat(ring_joint, sides)
    pos = _to_world(skel.bind_world, vj, local)
    nrm = np.einsum("vij,vj->vi", skel.bind_world[vj, :3, :3], nloc)
    uv = np.stack(
        [np.tile(np.arange(sides) / sides, rings), np.repeat(np.arange(rings, dtype=float), sides)], axis=-1
    )
    # quads between consecutive rings, counter-clockwise seen from outside
    r, s = np.meshgrid(np.arange(rings - 1), np.arange(sides), indexing="ij")
    v00 = r * sides + s
    v01 = r * sides + (s + 1) % sides
    v10 = v00 + sides
    v11 = v01 + sides
    idx = np.stack([v00, v01, v11, v00, v11, v10], axis=-1).reshape(-1)
    # skin: interior rings blend their joint with the parent joint, ends are rigid
    joints = np.zeros((len(pos), 4), np.uint16)
    weights = np.zeros((len(pos), 4), np.float32)
    joints[:, 0] = vj
    blend = (vj > 0) & (np.repeat(np.arange(rings), sides) < J)
    joints[blend, 1] = vj[blend] - 1
    weights[:, 0] = np.where(blend, 0.75, 1.0)
    weights[:, 1] = np.where(blend, 0.25, 0.0)
    return Primitive(
        "bark",
        "bark",
        pos.astype(np.float32),
        nrm.astype(np.float32),
        uv.astype(np.float32),
        idx.astype(np.uint32),
        joints,
        weights,
    )


def leaves(skel: Skeleton, n_leaves: int, size: float = 0.4) -> Primitive:
    """Quads carried rigidly (weight 1) by the last joints, sticking out sideways."""
    J = len(skel.names)
    lj = (J - 1 - np.arange(n_leaves) % J).astype(np.uint16)
    side = np.where(np.arange(n_leaves) % 2 == 0, 1.0, -1.0)
    corner = np.array([[0.0, -0.5, 0.0], [1.0, -0.5, 0.0], [1.0, 0.5, 0.0], [0.0, 0.5, 0.0]])
    local = (corner[None] * size) * np.array([1.0, 1.0, 1.0])
    local = local * np.stack([side, np.ones(n_leaves), np.ones(n_leaves)], -1)[:, None, :]
    local[..., 0] += 0.3 * side[:, None]
    local[..., 2] += 0.5
    vj = np.repeat(lj, 4)
    pos = _to_world(skel.bind_world, vj.astype(np.int64), local.reshape(-1, 3))
    nloc = np.repeat(np.stack([np.zeros(n_leaves), np.zeros(n_leaves), np.ones(n_leaves)], -1), 4, 0)
    nrm = np.einsum("vij,vj->vi", skel.bind_world[vj, :3, :3], nloc)
    uv = np.tile([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]], (n_leaves, 1))
    base = 4 * np.arange(n_leaves)[:, None]
    flip = side[:, None] < 0  # mirrored quads: swap winding to stay counter-clockwise
    tri = np.where(flip, [0, 2, 1, 0, 3, 2], [0, 1, 2, 0, 2, 3]) + base
    joints = np.zeros((4 * n_leaves, 4), np.uint16)
    joints[:, 0] = vj
    weights = np.zeros((4 * n_leaves, 4), np.float32)
    weights[:, 0] = 1.0
    return Primitive(
        "leaves",
        "leaf",
        pos.astype(np.float32),
        nrm.astype(np.float32),
        uv.astype(np.float32),
        tri.reshape(-1).astype(np.uint32),
        joints,
        weights,
    )


def sway_clip(
    skel: Skeleton, name: str, n_keys: int = 9, duration: float = 2.0, sparse: bool = False
) -> Clip:
    """Every non-root joint rocks about X and Y; the last key equals the first (loops).

    sparse=True keeps every other key on joints 1.. (identical sets, so writers can share one
    input accessor) and every key on the root (which never moves, so it gets no channel)."""
    J = len(skel.names)
    times = np.linspace(0.0, duration, n_keys)
    phase = 2 * np.pi * times / duration
    amp = np.deg2rad(4.0) * (1 + np.arange(J))
    ax = np.sin(phase)[:, None] * amp[None]
    ay = 0.5 * np.sin(2 * phase)[:, None] * amp[None]
    ax[:, 0] = ay[:, 0] = 0.0
    sway = Rotation.from_rotvec(np.stack([ax, ay, np.zeros_like(ax)], -1).reshape(-1, 3))
    rest = Rotation.from_quat(np.repeat(skel.rest_rotation[None], n_keys, 0).reshape(-1, 4))
    rot = (rest * sway).as_quat().reshape(n_keys, J, 4)
    rot[-1] = rot[0]
    keys = None
    if sparse:
        every = np.arange(n_keys)
        other = np.unique(np.r_[every[::2], n_keys - 1])
        keys = [every] + [other] * (J - 1)
    return Clip(name=name, times=times, rotations=rot, keys=keys)


MATERIALS = [
    Material("bark", (0.36, 0.27, 0.19, 1.0), roughness=0.9),
    Material("leaf", (0.25, 0.5, 0.15, 1.0), roughness=0.6, double_sided=True, alpha_cutoff=0.5),
]

# per LOD: joints, tube sides, leaf quads, distance, screen coverage
LOD_TABLE = [(3, 6, 2, 0.0, 0.5), (2, 4, 1, 30.0, 0.2), (2, 3, 1, 130.0, 0.05)]


def synthetic_asset(lods: int = 1, with_clip: bool = True) -> Asset:
    """lods in 1..3. LOD0: 3 joints, 6-sided tube (4 rings × 6 = 24 bark vertices, 36
    triangles), 2 leaf quads (8 vertices, 4 triangles); clip `wind_lod0` with sparse keys."""
    out = []
    for k, (J, sides, n_leaves, dist, cover) in enumerate(LOD_TABLE[:lods]):
        skel = chain_skeleton(J)
        clips = [sway_clip(skel, f"wind_lod{k}", sparse=(k == 0))] if with_clip else []
        out.append(
            Lod(
                primitives=[bark(skel, sides), leaves(skel, n_leaves)],
                skeleton=skel,
                clips=clips,
                distance=dist,
                screen_coverage=cover,
            )
        )
    return Asset(
        name="synthetic",
        materials=list(MATERIALS),
        lods=out,
        extras={"species": "synthetic", "seed": 0, "treegen": "test"},
    )


def synthetic_textures(size: int = 32) -> dict[str, Texture]:
    """Small real PNGs by role, as the materials stage will attach them: "leaf" (RGBA atlas,
    alpha cut-out, CLAMP), "bark" (sRGB albedo, REPEAT), "bark_normal" (raw, REPEAT)."""
    from treegen_cli.texture_bark import bark_textures
    from treegen_cli.texture_leaf import leaf_atlas
    from treegen_cli.texture_png import png_bytes

    atlas = leaf_atlas(0, (0.1, 0.3, 0.05), size=size, variants=1)
    albedo, normal = bark_textures((0.2, 0.15, 0.1), size=size)
    return {
        "leaf": Texture("leaf", png_bytes(atlas.rgba), wrap="CLAMP"),
        "bark": Texture("bark", png_bytes(albedo)),
        "bark_normal": Texture("bark_normal", png_bytes(normal), srgb=False),
    }


def textured_asset(lods: int = 1, with_clip: bool = True, size: int = 32) -> Asset:
    """synthetic_asset with a leaf atlas on the leaf material and albedo + normal map on the
    bark (the contract of asset.Material's texture fields)."""
    from dataclasses import replace

    tex = synthetic_textures(size)
    bark, leaf = MATERIALS
    materials = [
        replace(bark, base_texture=tex["bark"], normal_texture=tex["bark_normal"]),
        replace(leaf, base_texture=tex["leaf"]),
    ]
    return replace(synthetic_asset(lods, with_clip), materials=materials)
