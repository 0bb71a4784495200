"""Tree + Rig → skinned triangle lists: bark tubes along every stem and a card per leaf.

Result: one "bark" primitive (a ring of `sides + 1` vertices per ring, seam column duplicated for
UVs, each stem closed by a cone to an apex vertex) and one "leaves" primitive, both bound to the
rig's joints. Leaves are cards by default: one length × width quad per leaf (4 vertices,
2 triangles, UVs 0..1) meant for an alpha-tested texture that carries the LeafShape outline —
half the vertices of the 8-point ellipse on the willow's 630k leaves. `leaf_geometry="shape"`
stamps the LeafShape outline itself as geometry instead. Either way `Tree.leaf_area` stays the
physical blade area (length × width × fill_factor): a card draws length × width, the texture's
alpha cuts it back to the blade. Bark vertex layout: the
ring vertices stem by stem (base to tip), then one apex vertex per stem in stem order, so no
stem, however thin, is ever dropped.

UVs (origin bottom-left, as every Primitive's):
* Leaves: each leaf draws one cell of the leaf atlas (`MeshOptions.leaf_cells`, the layout the
  materials stage made the texture with), chosen by a generator seeded from the tree seed, and
  the card (or outline) fills that cell as textures.card_uvs maps it.
* Bark: u runs once around every stem (0 → 1 over the sides, seam column duplicated); v runs
  along it in metres of bark divided by the tile height, the stem's own base circumference, so
  texels are square at every stem's base (twigs get finer bark than the trunk, as real ones
  have). A stem longer than BARK_MAX_TILES circumferences (thin whips: most of the willow's
  twigs) gets taller tiles instead, span / BARK_MAX_TILES, so no stem needs more. Each stem
  starts at its own seeded (u, v) offset in [0, 1) so neighbouring stems' bark does not line
  up, and is then shifted by a whole number of tiles (invisible: the texture repeats) to centre
  its v range on 0. Hence v is continuous and increasing along every stem with no wraps, and
  |v| ≤ BARK_MAX_TILES / 2 + 1, |u| < 2: engines that store UVs as half floats keep at least
  1/64 of a tile of precision (a 256² texture: 4 texels) even at the ends of the longest stems.

    prims = build_mesh(tree, rig, MeshOptions(sides=(24, 10, 6, 4)))

Everything is ragged-array arithmetic over all stems at once (np.repeat / cumsum): no Python loop
over stems, rings, leaves or vertices (only over the few trunk stems for their flare rings).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
from scipy.spatial.transform import Rotation

from .asset import Primitive
from .errors import TreegenError
from .leafshapes import OUTLINES, outline
from .shapes import flare_factor, taper_radius
from .textures import card_uvs

FULL_CARD_CELL = ((0.0, 0.0, 1.0, 1.0),)  # one cell, the whole image: the card fills it
BARK_MAX_TILES = 64.0  # most texture tiles along one stem (see UVs above)


@dataclass(frozen=True)
class MeshOptions:
    """Per-level tuples index by stem level; their last entry repeats for deeper levels."""

    sides: tuple[int, ...] = (16, 8, 6, 4, 3)  # cross-section sides per level (>= 3)
    rings_per_segment: tuple[int, ...] = (2, 1)  # rings per segment per level (>= 1): more rings
    # bend more smoothly under skinning
    flare_rings: int = 4  # extra trunk rings in the flare zone (lowest 1/8 of the trunk)
    thin_radius: float = 0.002  # metres: stems with a thinner base radius get thin_sides
    thin_sides: int = 3
    cap_height: float = 0.5  # tip cap cone height / tip radius
    point_radius: float = 1e-4  # metres: tips thinner than this end in a point, not a cap,
    point_ratio: float = 0.02  # ... and so do tips thinner than this × the stem's base radius
    leaves: bool = True  # emit the "leaves" primitive
    leaf_geometry: str = "card"  # "card": a textured quad per leaf; "shape": the LeafShape
    # outline as geometry (see leafshapes.py)
    leaf_cells: tuple[tuple[float, float, float, float], ...] = FULL_CARD_CELL
    # leaf atlas layout: per variant its card rectangle
    # (u0, v0, u1, v1) in glTF UVs (top-left origin), as
    # textures.LeafAtlas.rects; materials.Materials gives it


MESH_DEFAULTS = MeshOptions()
LEAF_GEOMETRIES = ("card", "shape")
CARD = OUTLINES[4]  # the full length × width rectangle, UVs 0..1


def _per_level(values: tuple, level: np.ndarray) -> np.ndarray:
    v = np.asarray(values)
    return v[np.minimum(level, len(v) - 1)]


def stem_sides(tree, options: MeshOptions) -> np.ndarray:
    """Cross-section sides per stem (S,): per level, raised on a lobed trunk so the lobes show,
    cut to thin_sides on stems thinner than thin_radius."""
    level = tree.stem_level.astype(np.int64)
    p = tree.params
    sides = _per_level(options.sides, level).astype(np.int64)
    if p.lobes > 0 and p.lobe_depth != 0:
        sides = np.where(level == 0, np.maximum(sides, 4 * p.lobes), sides)
    return np.where(tree.stem_radius < options.thin_radius, np.minimum(sides, options.thin_sides), sides)


def pointed_tips(tree, options: MeshOptions) -> np.ndarray:
    """Bool (S,): stems whose tip is thin enough to close on an apex instead of a capped ring."""
    tip = tree.stem_node_start.astype(np.int64) + tree.stem_node_count - 1
    return tree.node_radius[tip] < np.maximum(options.point_radius, options.point_ratio * tree.stem_radius)


def merge_influences(joints: np.ndarray, weights: np.ndarray):
    """(K, n ≤ 4) joint/weight slots → (K, 4): duplicates merged, sorted by weight, normalised,
    unused slots (0, 0.0).   Result: ([3, 5, 3, 0], [.2, .3, .5, 0]) → ([3, 5, 0, 0], [.7, .3, 0, 0])"""
    K, n = joints.shape
    J = np.zeros((K, 4), dtype=np.int64)
    W = np.zeros((K, 4), dtype=np.float64)
    J[:, :n] = joints
    W[:, :n] = weights
    for j in range(1, 4):
        for i in range(j):
            dup = (J[:, j] == J[:, i]) & (W[:, i] > 0)
            W[dup, i] += W[dup, j]
            W[dup, j] = 0.0
    order = np.argsort(-W, axis=1, kind="stable")
    W = np.take_along_axis(W, order, axis=1)
    J = np.take_along_axis(J, order, axis=1)
    J[W <= 0] = 0
    W[W < 0] = 0.0
    W /= W.sum(axis=1, keepdims=True)
    return J.astype(np.uint16), W.astype(np.float32)


def _check(options: MeshOptions) -> None:
    if min(options.sides) < 3 or options.thin_sides < 3:
        raise TreegenError(f"--sides {options.sides}: every level needs at least 3 sides")
    if min(options.rings_per_segment) < 1:
        raise TreegenError(f"rings per segment {options.rings_per_segment}: must be >= 1")
    if options.leaf_geometry not in LEAF_GEOMETRIES:
        raise TreegenError(
            f"--leaf-geometry '{options.leaf_geometry}': expected one of {', '.join(LEAF_GEOMETRIES)}"
        )
    cells = np.asarray(options.leaf_cells, dtype=np.float64)
    if cells.ndim != 2 or cells.shape[1] != 4 or not len(cells) or not np.all(np.isfinite(cells)):
        raise ValueError(f"leaf_cells must be (u0, v0, u1, v1) rectangles, got {options.leaf_cells!r}")


def _ring_params(tree, options: MeshOptions):
    """Rings of every stem as (stem, u), u = segment index + fraction, sorted base to tip."""
    cnt = tree.stem_node_count.astype(np.int64)
    seg = cnt - 1
    m = _per_level(options.rings_per_segment, tree.stem_level.astype(np.int64)).astype(np.int64)
    n_rings = seg * m + 1
    stem = np.repeat(np.arange(tree.n_stems), n_rings)
    k = np.arange(stem.size) - np.repeat(np.cumsum(n_rings) - n_rings, n_rings)
    u = k / m[stem]
    flare = tree.params.flare
    trunks = np.flatnonzero((tree.stem_level == 0) & ~tree.stem_clone)
    if flare > 0 and options.flare_rings > 0 and trunks.size:
        # Flare grows as 100^(1 − 8Z): rings packed toward the base (quadratic spacing).
        Zs = (np.arange(1, options.flare_rings + 1) / (options.flare_rings + 1)) ** 2 / 8.0
        extra_s, extra_u = [], []
        for s in trunks:  # a handful of trunks at most
            nz = tree.node_z[tree.stem_node_start[s] : tree.stem_node_start[s] + cnt[s]]
            z = nz[0] + Zs * tree.stem_length[s]
            a = np.clip(np.searchsorted(nz, z, side="right") - 1, 0, seg[s] - 1)
            extra_u.append(a + (z - nz[a]) / np.maximum(nz[a + 1] - nz[a], 1e-12))
            extra_s.append(np.full(len(z), s))
        stem = np.concatenate([stem, *extra_s])
        u = np.concatenate([u, *extra_u])
        order = np.lexsort((u, stem))
        stem, u = stem[order], u[order]
        keep = np.ones(stem.size, dtype=bool)
        keep[1:] = (stem[1:] != stem[:-1]) | (u[1:] - u[:-1] > 1e-4)
        stem, u = stem[keep], u[keep]
    return stem, u


def bark_offsets(tree) -> np.ndarray:
    """(S, 2) seeded (u, v) bark offsets in [0, 1), one pair per stem, so neighbouring stems'
    bark does not line up. Stems are ordered level by level, so a LOD that regrows the tree
    with fewer levels keeps its stems' offsets (the same stream, a prefix of it)."""
    rng = np.random.default_rng([int(tree.seed), 0xBA4C, 0x0FF5])
    return rng.random((tree.n_stems, 2))


def leaf_variants(tree, n_cells: int) -> np.ndarray:
    """Atlas cell per leaf (L,), seeded from the tree seed: the same tree, the same leaves."""
    if n_cells <= 1:
        return np.zeros(tree.n_leaves, dtype=np.int64)
    rng = np.random.default_rng([int(tree.seed), 0x1EAF, 0xA71A5])
    return rng.integers(0, n_cells, tree.n_leaves)


def _bark(tree, rig, options: MeshOptions) -> Primitive:
    S = tree.n_stems
    level = tree.stem_level.astype(np.int64)
    cnt = tree.stem_node_count.astype(np.int64)
    start = tree.stem_node_start.astype(np.int64)
    F = tree.node_frame
    p = tree.params

    # --- rings: centre, frame, radius, z, binding (all rings, tip rings included) ---
    rs, u = _ring_params(tree, options)
    a_loc = np.minimum(np.floor(u).astype(np.int64), cnt[rs] - 2)
    t = u - a_loc
    a = start[rs] + a_loc
    b = a + 1
    centre = tree.node_pos[a] + t[:, None] * (tree.node_pos[b] - tree.node_pos[a])
    frame = np.where((t >= 1.0 - 1e-9)[:, None, None], F[b], F[a])
    # A ring on an interior node takes the frame halfway between its two segments, so a bend
    # does not pinch the incoming tube against the outgoing one.
    bend = np.flatnonzero((t <= 1e-9) & (a_loc > 0))
    if bend.size:
        r_in = Rotation.from_matrix(F[a[bend] - 1])
        half = Rotation.from_rotvec(0.5 * (r_in.inv() * Rotation.from_matrix(F[a[bend]])).as_rotvec())
        frame[bend] = (r_in * half).as_matrix()
    z = tree.node_z[a] + t * (tree.node_z[b] - tree.node_z[a])
    trunk = level[rs] == 0
    length = np.maximum(tree.stem_length[rs], 1e-12)
    # Between nodes the radius follows the species' taper × flare profile, rescaled so that it
    # passes exactly through the generator's node radii.
    taper = np.array([lp.taper for lp in p.level])[np.minimum(level[rs], len(p.level) - 1)]
    r0 = tree.stem_radius[rs]

    def profile(zz):
        prof = taper_radius(r0, length, taper, zz)
        return np.where(trunk, prof * flare_factor(p.flare, zz / length), prof)

    def fit(r_node, prof):
        return np.where(prof > 0, r_node / np.where(prof > 0, prof, 1.0), 1.0)

    radius = (
        fit(tree.node_radius[a], profile(tree.node_z[a])) * (1 - t)
        + fit(tree.node_radius[b], profile(tree.node_z[b])) * t
    ) * profile(z)

    n_all = np.bincount(rs, minlength=S)
    first = np.cumsum(n_all) - n_all
    last = first + n_all - 1
    i = np.arange(rs.size)
    ip, inx = np.maximum(i - 1, first[rs]), np.minimum(i + 1, last[rs])
    slope = (radius[inx] - radius[ip]) / np.maximum(z[inx] - z[ip], 1e-12)  # dr/ds

    # Pointed tips drop their zero-radius ring and close on the apex; others get a cone cap.
    tip = start + cnt - 1
    pointed = pointed_tips(tree, options)
    emit = ~(pointed[rs] & (i == last[rs]))
    rs, centre, frame, z, radius, slope, a, b, t = (
        x[emit] for x in (rs, centre, frame, z, radius, slope, a, b, t)
    )
    trunk = level[rs] == 0
    R = rs.size

    # --- bark UVs per stem: tile height, seeded offsets, centring shift (module docstring) ---
    cap = np.where(pointed, 0.0, options.cap_height * tree.node_radius[tip])
    z_base = tree.node_z[start]
    span = tree.node_z[tip] + cap - z_base  # metres of bark, cap included
    tile = np.maximum(2.0 * np.pi * np.maximum(tree.stem_radius, 1e-6), span / BARK_MAX_TILES)
    off_u, off_v = bark_offsets(tree).T
    v_shift = off_v - np.round(0.5 * (span / tile + off_v))
    v_ring = (z - z_base[rs]) / tile[rs] + v_shift[rs]

    lobed = p.lobes > 0 and p.lobe_depth != 0
    sides = stem_sides(tree, options)
    sd = sides[rs]
    nv = sd + 1  # seam column duplicated for UVs
    v0 = np.cumsum(nv) - nv
    Vr = int(nv.sum())

    # --- ring vertices, one broadcast per distinct side count (a handful of groups) ---
    pos_r = np.empty((Vr, 3), dtype=np.float32)
    nrm_r = np.empty((Vr, 3), dtype=np.float32)
    uv_r = np.empty((Vr, 2), dtype=np.float32)
    tan_r = np.empty((Vr, 3), dtype=np.float32)
    for n in np.unique(sd):
        g = np.flatnonzero(sd == n)
        col = np.arange(n + 1)
        theta = 2.0 * np.pi * col / n
        c, s_ = np.cos(theta)[None, :, None], np.sin(theta)[None, :, None]
        fr = frame[g]
        radial = c * fr[:, None, :, 0] + s_ * fr[:, None, :, 1]  # (Rg, n+1, 3)
        if lobed:
            on = trunk[g][:, None]
            lf = np.where(on, 1.0 + p.lobe_depth * np.sin(p.lobes * theta), 1.0)
            dlf = np.where(on, p.lobe_depth * p.lobes * np.cos(p.lobes * theta), 0.0)
        else:
            lf, dlf = np.ones((1, n + 1)), np.zeros((1, n + 1))
        dest = (v0[g][:, None] + col[None, :]).ravel()
        pos_r[dest] = (centre[g][:, None, :] + (radius[g][:, None] * lf)[:, :, None] * radial).reshape(-1, 3)
        # Normal of c(s) + r(s)·f(θ)·radial(θ): f·radial − f'·tangent − f²·r'(s)·axis.
        tangent = -s_ * fr[:, None, :, 0] + c * fr[:, None, :, 1]
        nr = (
            lf[:, :, None] * radial
            - dlf[:, :, None] * tangent
            - (lf * lf * slope[g][:, None])[:, :, None] * fr[:, None, :, 2]
        )
        nr /= np.linalg.norm(nr, axis=2, keepdims=True)
        nrm_r[dest] = nr.reshape(-1, 3)
        # Tangent (for the bark normal map): +u runs with θ, made orthogonal to the normal.
        tg = tangent - np.einsum("rck,rck->rc", tangent, nr)[:, :, None] * nr
        tg /= np.linalg.norm(tg, axis=2, keepdims=True)
        tan_r[dest] = tg.reshape(-1, 3)
        uv_r[dest, 0] = (col[None, :] / n + off_u[rs[g]][:, None]).ravel()
        uv_r[dest, 1] = np.repeat(v_ring[g], n + 1)
    rv = np.repeat(np.arange(R), nv)

    ring_J = np.concatenate([rig.node_joints[a], rig.node_joints[b]], axis=1)
    ring_W = np.concatenate(
        [rig.node_weights[a] * (1 - t)[:, None], rig.node_weights[b] * t[:, None]], axis=1
    )
    ring_J, ring_W = merge_influences(ring_J, ring_W)

    # --- apex per stem (tip point, or a low cone over a blunt tip) ---
    axis = F[tip][:, :, 2]
    pos_a = tree.node_pos[tip] + cap[:, None] * axis
    uv_a = np.column_stack([0.5 + off_u, span / tile + v_shift])
    apex_J, apex_W = merge_influences(rig.node_joints[tip], rig.node_weights[tip])

    # --- triangles: quads between consecutive rings of a stem, then a fan to the apex ---
    pair = np.flatnonzero(rs[1:] == rs[:-1])
    qn = sd[pair]
    qp = np.repeat(pair, qn)
    qj = np.arange(qp.size) - np.repeat(np.cumsum(qn) - qn, qn)
    q0 = v0[qp] + qj
    q3 = v0[qp + 1] + qj
    quads = np.stack([q0, q0 + 1, q3 + 1, q0, q3 + 1, q3], axis=1).reshape(-1, 3)
    n_emit = np.bincount(rs, minlength=S)
    last_ring = np.cumsum(n_emit) - 1
    fs = np.repeat(np.arange(S), sides)
    fj = np.arange(fs.size) - np.repeat(np.cumsum(sides) - sides, sides)
    l0 = v0[last_ring[fs]] + fj
    fans = np.stack([l0, l0 + 1, Vr + fs], axis=1)

    # Tangents: w = +1, as cross(normal, +u around the stem) points up the stem (+v); the
    # apex takes its frame's x axis (its normal is the stem axis).
    tangents = np.ones((Vr + S, 4), dtype=np.float32)
    tangents[:Vr, :3] = tan_r
    tangents[Vr:, :3] = F[tip][:, :, 0]
    return Primitive(
        name="bark",
        material="bark",
        positions=np.concatenate([pos_r, pos_a]).astype(np.float32),
        normals=np.concatenate([nrm_r, axis]).astype(np.float32),
        tangents=tangents,
        uvs=np.concatenate([uv_r, uv_a]).astype(np.float32),
        indices=np.concatenate([quads, fans]).astype(np.uint32).ravel(),
        joints=np.concatenate([ring_J[rv], apex_J]),
        weights=np.concatenate([ring_W[rv], apex_W]),
    )


def _faces_flat(o) -> bool:
    """Whether every outline vertex normal is the face normal of its triangles, also after the
    stamp's anisotropic length × width scaling (checked at two aspect ratios)."""
    for aspect in (1.0, 3.0):
        p = o.points * [1.0, aspect, 1.0]
        a, b, c = (p[o.triangles[:, k]] for k in range(3))
        fn = np.cross(b - a, c - a)
        fn /= np.linalg.norm(fn, axis=1, keepdims=True)
        if not np.allclose(o.normals[o.triangles], fn[:, None, :], atol=1e-9):
            return False
    return True


def _leaf_uvs(tree, o, cells) -> np.ndarray:
    """(L·P, 2) bottom-left UVs: each leaf's outline points in its seeded atlas cell. card_uvs
    maps the P points into each of the few cells once; leaves then index that small table."""
    K, P = len(cells), len(o.points)
    table = card_uvs(
        np.tile(o.uvs, (K, 1)),
        np.repeat(np.arange(K), P),
        SimpleNamespace(rects=np.asarray(cells, dtype=np.float32)),  # reads .rects
        origin="bottom-left",
    )
    pick = leaf_variants(tree, K)[:, None] * P + np.arange(P)[None, :]
    return table[pick.ravel()]


def _leaves(tree, rig, geometry: str = "card", cells: tuple = FULL_CARD_CELL) -> Primitive:
    """Stamp a card (or the LeafShape outline) on every leaf frame (float32 broadcasts)."""
    o = outline(tree.params.leaf_shape)  # validates the code even for cards
    if geometry == "card":
        o = CARD
    L, P = tree.n_leaves, len(o.points)
    F = tree.leaf_frame.astype(np.float32)
    size = tree.leaf_size.astype(np.float32)
    length, width = size[:, 0:1], size[:, 1:2]  # (L, 1)
    pts = o.points.astype(np.float32)
    base = tree.leaf_pos.astype(np.float32)
    # Blade axes scaled once, then one (L, 3) pass per outline point (P ≤ 16, not per leaf).
    across, along = F[:, :, 0] * width, F[:, :, 1] * length
    up = F[:, :, 2] * width if np.any(pts[:, 2]) else None  # folded blades (palm)
    pos = np.empty((L, P, 3), dtype=np.float32)
    for k, (x, y, z) in enumerate(pts):
        out = pos[:, k]
        np.multiply(across, x, out=out)
        out += base
        if y:
            out += y * along
        if z and up is not None:
            out += z * up
    nl = o.normals.astype(np.float32)
    if np.all(nl == [0.0, 0.0, 1.0]):  # flat blade: the frame normal
        n = F[:, :, 2]
        n = n / np.sqrt(np.einsum("ij,ij->i", n, n))[:, None]
        nrm = np.repeat(n, P, axis=0)
    else:
        nrm = (
            nl[None, :, 0, None] * F[:, None, :, 0]
            + nl[None, :, 1, None] * F[:, None, :, 1]
            + nl[None, :, 2, None] * F[:, None, :, 2]
        )
        nrm = (nrm / np.linalg.norm(nrm, axis=2, keepdims=True)).reshape(-1, 3)
    idx = (
        o.triangles.astype(np.uint32)[None, :, :]
        + (np.uint32(P) * np.arange(L, dtype=np.uint32))[:, None, None]
    )
    joints = np.zeros((L * P, 4), dtype=np.uint16)
    joints[:, 0] = np.repeat(rig.leaf_joint, P)
    weights = np.zeros((L * P, 4), dtype=np.float32)
    weights[:, 0] = 1.0
    return Primitive(
        name="leaves",
        material="leaf",
        positions=pos.reshape(-1, 3),
        normals=nrm,
        uvs=_leaf_uvs(tree, o, cells),
        indices=idx.ravel(),
        joints=joints,
        weights=weights,
        flat_normals=_faces_flat(o),  # frames are rotations: flat stays flat
    )


def build_mesh(tree, rig, options: MeshOptions = MESH_DEFAULTS) -> list[Primitive]:
    """Bark (always) and leaves (when the tree has any and options.leaves), skinned to `rig`."""
    _check(options)
    prims = [_bark(tree, rig, options)]
    if options.leaves and tree.n_leaves:
        prims.append(_leaves(tree, rig, options.leaf_geometry, options.leaf_cells))
    return prims
