"""Bark: a tube along every stem, closed by a cone (or a point) at its tip, skinned to the rig.

Vertex layout: a ring of `sides + 1` vertices (seam column duplicated for UVs) per ring, the
rings stem by stem (base to tip), then one apex vertex per stem in stem order, so no stem,
however thin, is ever dropped (a far LOD's thin branches are drawn as crossed ribbons
instead, the same rings in ribbons.py's "twigs" primitive). Between nodes the radius follows
the species' taper × flare profile, through the generator's node radii; a lobed trunk (Lobes,
LobeDepth) gets normals of the lobed surface.

UVs (origin bottom-left): u runs once around every stem (0 → 1 over the sides, seam column
duplicated); v runs along it in metres of bark divided by the tile height, the stem's own base
circumference, so texels are square at every stem's base (twigs get finer bark than the trunk,
as real ones have). A stem longer than BARK_MAX_TILES circumferences (thin whips: most of the
willow's twigs) gets taller tiles instead, span / BARK_MAX_TILES, so no stem needs more. Each
stem starts at its own seeded (u, v) offset in [0, 1) so neighbouring stems' bark does not line
up, and is then shifted by a whole number of tiles (invisible: the texture repeats) to centre
its v range on 0. Hence v is continuous and increasing along every stem with no wraps, and
|v| ≤ BARK_MAX_TILES / 2 + 1, |u| < 2: engines that store UVs as half floats keep at least
1/64 of a tile of precision (a 256² texture: 4 texels) even at the ends of the longest stems.
"""

from __future__ import annotations

import numpy as np

from ..asset import Primitive
from ..shapes import flare_factor, taper_radius
from .influences import merge_influences
from .options import MeshOptions, girth, per_level, pointed_tips, ribbon_stems, stem_sides
from .ribbons import ribbons

BARK_MAX_TILES = 64.0  # most texture tiles along one stem (see UVs above)


def _flare_rings(tree, options: MeshOptions) -> list[tuple[int, np.ndarray]]:
    """(trunk, u of its extra flare rings) per trunk: Flare grows as 100^(1 − 8Z), so rings
    are packed toward the base (quadratic spacing in the lowest 1/8)."""
    if not (tree.params.flare > 0 and options.flare_rings > 0):
        return []
    cnt = tree.stem_node_count.astype(np.int64)
    Zs = (np.arange(1, options.flare_rings + 1) / (options.flare_rings + 1)) ** 2 / 8.0
    out = []
    for s in np.flatnonzero((tree.stem_level == 0) & ~tree.stem_clone):  # a handful at most
        seg = cnt[s] - 1
        nz = tree.node_z[tree.stem_node_start[s] : tree.stem_node_start[s] + cnt[s]]
        z = nz[0] + Zs * tree.stem_length[s]
        a = np.clip(np.searchsorted(nz, z, side="right") - 1, 0, seg - 1)
        out.append((int(s), a + (z - nz[a]) / np.maximum(nz[a + 1] - nz[a], 1e-12)))
    return out


def _flared(tree, options: MeshOptions, m: np.ndarray) -> dict[int, np.ndarray]:
    """Each flared trunk's rings (u, sorted): its node rings (`m` (S,) per segment) and its
    flare rings, one within 1e-4 of the ring before merged into it (a fine CurveRes puts
    flare rings on node rings)."""
    out = {}
    for s, x in _flare_rings(tree, options):
        u = np.sort(np.concatenate([np.arange((tree.stem_node_count[s] - 1) * m[s] + 1) / m[s], x]))
        out[s] = u[np.r_[True, np.diff(u) > 1e-4]]
    return out


def ring_params(tree, options: MeshOptions):
    """Rings of every stem as (stem, u), u = segment index + fraction, sorted base to tip."""
    cnt = tree.stem_node_count.astype(np.int64)
    seg = cnt - 1
    m = per_level(options.rings_per_segment, tree.stem_level.astype(np.int64)).astype(np.int64)
    n_rings = seg * m + 1
    stem = np.repeat(np.arange(tree.n_stems), n_rings)
    k = np.arange(stem.size) - np.repeat(np.cumsum(n_rings) - n_rings, n_rings)
    u = k / m[stem]
    flared = _flared(tree, options, m)
    if flared:  # the trunks' rings replaced by theirs with the flare rings
        rest = ~np.isin(stem, list(flared))
        stem = np.concatenate([stem[rest], *(np.full(len(x), s) for s, x in flared.items())])
        u = np.concatenate([u[rest], *flared.values()])
        order = np.lexsort((u, stem))
        stem, u = stem[order], u[order]
    return stem, u


def ring_counts(tree, options: MeshOptions) -> np.ndarray:
    """Rings per stem (S,) as ring_params places them, without placing every stem's: a fine
    CurveRes puts flare rings on node rings, which merge (limits counted them twice)."""
    seg = tree.stem_node_count.astype(np.int64) - 1
    m = per_level(options.rings_per_segment, tree.stem_level.astype(np.int64)).astype(np.int64)
    rings = seg * m + 1
    for s, x in _flared(tree, options, m).items():
        rings[s] = len(x)
    return rings


def bark_offsets(tree) -> np.ndarray:
    """(S, 2) seeded (u, v) bark offsets in [0, 1), one pair per stem, so neighbouring stems'
    bark does not line up. Stems are ordered level by level, so a LOD that regrows the tree
    with fewer levels keeps its stems' offsets (the same stream, a prefix of it)."""
    rng = np.random.default_rng([int(tree.seed), 0xBA4C, 0x0FF5])
    return rng.random((tree.n_stems, 2))


def bark_primitives(tree, rig, options: MeshOptions) -> list[Primitive]:
    """The "bark" primitive: every stem's tube and tip (layout and UVs: the module docstring);
    and where a far LOD draws its thin branches as crossed ribbons (MeshOptions.ribbon_radius),
    the "twigs" primitive holding those."""
    S = tree.n_stems
    level = tree.stem_level.astype(np.int64)
    cnt = tree.stem_node_count.astype(np.int64)
    start = tree.stem_node_start.astype(np.int64)
    F = tree.node_frame
    p = tree.params

    # --- rings: centre, frame, radius, z, binding (all rings, tip rings included) ---
    rs, u = ring_params(tree, options)
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
        from scipy.spatial.transform import Rotation  # (0.2 s to import: only where used)

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

    # --- bark UVs per stem: tile height, seeded offsets, centring shift (module docstring) ---
    cap = np.where(pointed, 0.0, options.cap_height * tree.node_radius[tip])
    z_base = tree.node_z[start]
    span = tree.node_z[tip] + cap - z_base  # metres of bark, cap included
    tile = np.maximum(2.0 * np.pi * np.maximum(tree.stem_radius, 1e-6), span / BARK_MAX_TILES)
    off_u, off_v = bark_offsets(tree).T
    v_shift = off_v - np.round(0.5 * (span / tile + off_v))
    v_ring = (z - z_base[rs]) / tile[rs] + v_shift[rs]

    sides = stem_sides(tree, options)
    radius = radius * girth(tree, options, sides)[rs]  # a LOD's few sides as wide as LOD0's many
    ribbon = ribbon_stems(tree, options)
    rib = ribbon[rs]
    twigs = None
    if rib.any():
        twigs = ribbons(
            tree,
            rig,
            pointed,
            rs[rib],
            centre[rib],
            frame[rib],
            radius[rib],
            v_ring[rib],
            a[rib],
            b[rib],
            t[rib],
            off_u,
            span / tile + v_shift,
        )
        rs, centre, frame, z, radius, slope, a, b, t, v_ring = (
            x[~rib] for x in (rs, centre, frame, z, radius, slope, a, b, t, v_ring)
        )
    trunk = level[rs] == 0
    R = rs.size

    lobed = p.lobes > 0 and p.lobe_depth != 0
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

    # --- apex per tube (tip point, or a low cone over a blunt tip) ---
    tubes = np.flatnonzero(~ribbon)
    tip_t = tip[tubes]
    axis = F[tip_t][:, :, 2]
    pos_a = tree.node_pos[tip_t] + cap[tubes, None] * axis
    uv_a = np.column_stack([0.5 + off_u[tubes], span[tubes] / tile[tubes] + v_shift[tubes]])
    apex_J, apex_W = merge_influences(rig.node_joints[tip_t], rig.node_weights[tip_t])

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
    fn = sides[tubes]
    fe = np.repeat(np.arange(tubes.size), fn)  # the fan's apex: its tube's rank
    fj = np.arange(fe.size) - np.repeat(np.cumsum(fn) - fn, fn)
    l0 = v0[last_ring[tubes[fe]]] + fj
    fans = np.stack([l0, l0 + 1, Vr + fe], axis=1)

    # Tangents: w = +1, as cross(normal, +u around the stem) points up the stem (+v); the
    # apex takes its frame's x axis (its normal is the stem axis).
    tangents = np.ones((Vr + tubes.size, 4), dtype=np.float32)
    tangents[:Vr, :3] = tan_r
    tangents[Vr:, :3] = F[tip_t][:, :, 0]
    bark = Primitive(
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
    return [bark] if twigs is None else [bark, twigs]
