"""The impostor's atlas, drawn: which of a LOD's triangles go in, and how thinned leaves keep
the crown's cover.

    albedo, normal_depth, card_albedo, card_normal = render_views(
        coarse_lod, materials, centre, radius, options, cells)
    # Result: the two (size, size, 4) uint8 atlases, and the cards' views side by side at
    # options.card_cell px; transparent texels carry their view's mean colour (_dilate).

The views are a few pixels per leaf, so a crown of many leaves is drawn from every k-th leaf,
enlarged; the enlargement is measured (render_views), not assumed, and bark is drawn from its
widest triangles. impostor_render.py does the GL work.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .asset import TWIGS, Lod, Material, Primitive, triangle_areas
from .leafshapes import card_corners


def _corners(prim: Primitive) -> int:
    """Vertices a leaf of a leaf primitive (leafshapes.card_corners); 0 for bark."""
    return 0 if prim.material == "bark" else card_corners(len(prim.positions), len(prim.indices))


def _fewer_leaves(prim: Primitive, cap: int) -> Primitive:
    """Every k-th leaf card (or triangle card) of a primitive of more than `cap`, at its own
    size (render_views enlarges them until they cover what all the cards did); `prim` itself
    when there is nothing to thin."""
    P = _corners(prim)
    n = len(prim.positions) // P if P else 0
    if not P or n <= cap:
        return prim
    keep = np.arange(0, n, math.ceil(n / cap))
    verts = (P * keep[:, None] + np.arange(P)).ravel()
    per = 3 * (P - 2)  # indices a leaf
    first = np.asarray(prim.indices[:per], np.int64)  # the cards' shared index pattern
    idx = (first[None, :] + P * np.arange(len(keep))[:, None]).ravel().astype(np.uint32)
    return replace(
        prim,
        positions=np.asarray(prim.positions, np.float32)[verts],
        normals=np.asarray(prim.normals)[verts],
        uvs=np.asarray(prim.uvs)[verts],
        indices=idx,
        joints=np.asarray(prim.joints)[verts],
        weights=np.asarray(prim.weights)[verts],
    )


def _enlarged(part, area: float, corners: int):
    """A drawable part of `corners`-vertex leaves with each scaled about its centre to `area`×."""
    quads = np.asarray(part.positions, np.float64).reshape(-1, corners, 3)
    mid = quads.mean(1, keepdims=True)
    pos = (mid + (quads - mid) * math.sqrt(area)).reshape(-1, 3).astype(np.float32)
    return replace(part, positions=pos)


def _edges(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(T, 3) lengths of each triangle's edges, edge i from corner i to corner i + 1."""
    return np.linalg.norm(p[tri] - p[np.roll(tri, -1, axis=1)], axis=2)


def _widest_bark(prim: Primitive, cap: int) -> Primitive:
    """The `cap` bark triangles with the longest shortest edge (a tube's is its side width):
    trunk and limbs; twigs far below an atlas pixel are left out."""
    tri = np.asarray(prim.indices, np.int64).reshape(-1, 3)
    if len(tri) <= cap or prim.material != "bark":
        return prim
    edge = _edges(np.asarray(prim.positions, np.float64), tri)
    keep = np.sort(np.argsort(-edge.min(1), kind="stable")[:cap])
    return replace(prim, indices=tri[keep].ravel().astype(np.uint32))


MIN_BARK_TEXELS = 1.5  # stems are drawn at least this many atlas texels wide
WIDEN_SHARE = 0.1  # ... stems in full while what that adds is within this share of the
# view's cover, the least widened first; of the others only some are drawn (_bark_at_least)


TRUNK_SHARE = 0.25  # a stem holding this share of the bark is a trunk: always widened


def _bark_at_least(
    prim: Primitive, width: float, below: float, budget: float = math.inf
) -> tuple[Primitive, np.ndarray | None, float]:
    """Bark whose tubes are at least `width` metres wide below height `below` (the bole under
    the crown, whose leaves hide its limbs): each vertex pushed out along its (radial) normal
    by what its tube lacks; (V,) 1 where a vertex is drawn, 0 where not (None: all are); and
    the budget used (m²). A tube's radius is read from each edge between vertices whose
    normals differ by more than 20° (around a ring, not along the tube): chord / (2 sin(θ/2))
    for normals θ apart, the least over the vertex's edges (a diagonal to the next ring reads
    longer).

    A trunk thinner than a texel fell to the alpha test in small atlases: the `mobile`
    profile's aspen cards showed its crown floating. Widening every thin stem turned a rush's
    fan of stalks into a solid wedge (2.5× its coarsest LOD's cover). So stems (the mesh's
    connected pieces) are widened in full: a trunk, a stem of TRUNK_SHARE of the bark or more,
    always (a palm lost its own at small atlases, its crown floating), then the least widened first while
    the area that adds (a tube's surface / π) stays within `budget` m²; of the others, each
    standing for its true width's share of the widened area, one in so many is drawn (error
    diffusion in mesh order) and the rest are left out: fewer stalks, each a line, covering
    what all did."""
    if prim.material != "bark" or not len(prim.indices):
        return prim, None, 0.0
    from .impostor_shading import leaf_ids

    p = np.array(prim.positions, np.float64)  # a copy: moved below
    n = np.asarray(prim.normals, np.float64)
    tri = np.asarray(prim.indices, np.int64).reshape(-1, 3)
    a, b = tri.ravel(), np.roll(tri, -1, axis=1).ravel()  # every triangle edge, as _edges
    cos = np.einsum("ij,ij->i", n[a], n[b])
    around = cos < math.cos(math.radians(20.0))
    half_sin = np.sqrt(np.clip(0.5 * (1.0 - cos[around]), 1e-12, None))
    r = _edges(p, tri).ravel()[around] / (2.0 * half_sin)
    radius = np.full(len(p), np.inf)
    np.minimum.at(radius, a[around], r)
    np.minimum.at(radius, b[around], r)
    push = np.where(np.isfinite(radius) & (p[:, 2] < below), np.clip(0.5 * width - radius, 0.0, None), 0.0)
    moved = push > 0
    if not moved.any():
        return prim, None, 0.0
    before = triangle_areas(p, tri)
    p[moved] += push[moved, None] * n[moved]
    after = triangle_areas(p, tri)
    stem = leaf_ids(prim.indices, len(p))  # a connected piece of bark: a stem
    grown = moved[tri].any(axis=1)
    n_stems = int(stem.max()) + 1
    was = np.bincount(stem[tri[grown, 0]], before[grown], n_stems)
    now = np.bincount(stem[tri[grown, 0]], after[grown], n_stems)
    touched = np.flatnonzero(now > was)
    share = was[touched] / now[touched]  # of its widened area, what the stem truly shows
    added = (now[touched] - was[touched]) / math.pi
    area = np.bincount(stem[tri[:, 0]], before, n_stems)[touched]
    trunk = area >= TRUNK_SHARE * before.sum()  # (a rush's stalks: none)
    order = np.argsort(-share, kind="stable")
    order = np.concatenate([order[trunk[order]], order[~trunk[order]]])
    full = np.zeros(len(touched), bool)
    full[order] = np.cumsum(added[order]) <= budget
    full |= trunk
    drawn = np.ones(n_stems, bool)
    rest = touched[~full]
    if len(rest):  # error diffusion: the k-th is drawn when the running sum passes k - 1/2
        run = np.cumsum(share[~full])
        drawn[rest] = np.diff(np.floor(run + 0.5), prepend=0.0) > 0
    moved_prim = replace(prim, positions=p.astype(np.float32))
    return moved_prim, (None if drawn.all() else drawn[stem].astype(np.float32)), float(added[full].sum())


def _dilate(rgba: np.ndarray, cell: int) -> np.ndarray:
    """Transparent texels take their view's mean visible colour (alpha stays 0), so clients'
    mipmaps and bilinear filtering do not darken the cut-out's edges; `rgba` is rows × columns
    of `cell`-px views (the atlas, or the cards' strip). The renderer clears to 0, so a view's
    colour sum needs no mask; texels are filled as whole uint32 words."""
    rgba = np.ascontiguousarray(rgba)
    nr, nc = rgba.shape[0] // cell, rgba.shape[1] // cell
    rows = rgba.reshape(nr, cell, nc, cell * 4).sum(axis=1, dtype=np.uint32)
    total = rows.reshape(nr, nc, cell, 4).sum(axis=2)[..., :3]  # (nr, nc, 3)
    empty = (rgba[..., 3] == 0).reshape(nr, cell, nc, cell)
    count = np.maximum(cell * cell - np.count_nonzero(empty, axis=(1, 3)), 1).astype(np.uint32)
    fill = np.zeros((nr, nc, 4), np.uint8)
    fill[..., :3] = (total + count[..., None] // 2) // count[..., None]
    texels = rgba.view(np.uint32).reshape(nr, cell, nc, cell)
    out = np.where(empty, fill.view(np.uint32).reshape(nr, 1, nc, 1), texels)
    return out.view(np.uint8).reshape(rgba.shape)


def _shown(prims: list[Primitive]) -> tuple[float, float]:
    """(leaves, bark): the area a LOD shows from the side, roughly (m²): its leaves' one side
    (their cards'), its bark's surface / π (a tube's outline)."""
    out = [0.0, 0.0]
    for p in prims:
        bark = p.material == "bark"
        out[bark] += float(triangle_areas(p.positions, p.indices).sum()) / (math.pi if bark else 1.0)
    return out[0], out[1]


def _twigs_as_bark(prims: list[Primitive]) -> list[Primitive]:
    """`prims` with a far LOD's crossed ribbons (mesh TWIGS) drawn into its bark primitive as
    the square tubes through their vertices (mesh.ribbons_as_tubes), so they are widened or
    left out as thin bark is (drawn as they are, the fir's impostor crown showed every twig
    as a dark speck)."""
    from .mesh import ribbons_as_tubes

    twigs = [ribbons_as_tubes(p) for p in prims if p.material == TWIGS]
    if not twigs:
        return prims
    out = [p for p in prims if p.material != TWIGS]
    i = next(k for k, p in enumerate(out) if p.material == "bark")
    parts = [out[i], *twigs]
    base = np.cumsum([0] + [len(p.positions) for p in parts[:-1]])
    out[i] = replace(
        out[i],
        positions=np.concatenate([p.positions for p in parts]),
        normals=np.concatenate([p.normals for p in parts]),
        uvs=np.concatenate([p.uvs for p in parts]),
        indices=np.concatenate(
            [np.asarray(p.indices, np.uint32) + np.uint32(b) for p, b in zip(parts, base)]
        ),
        joints=np.concatenate([p.joints for p in parts]),
        weights=np.concatenate([p.weights for p in parts]),
        tangents=None,  # (the atlas draws no normal map)
    )
    return out


def _atlas_parts(prims: list[Primitive], materials: list[Material], decoded: dict | None = None) -> list:
    """What render_atlas draws, in generator space (Z up): each primitive with its material's
    colour, cut-out and base texture (decoded once, into `decoded` when given, so several
    calls share the images). Not drawable.from_asset: that would turn everything Y up and
    back, decode the unused normal maps and build a rig."""
    from .drawable import Part, decode_image

    mats = {m.name: m for m in materials}
    decoded = {} if decoded is None else decoded
    parts = []
    for p in prims:
        m = mats.get(p.material)
        has_uv = p.uvs is not None and len(p.uvs) == len(p.positions)
        tex = m.base_texture if m is not None and has_uv else None
        if tex is not None and id(tex) not in decoded:
            decoded[id(tex)] = decode_image(tex.png, 4, f"texture {tex.name!r}")
        wrap = tex.wrap if tex is not None and tex.wrap in ("REPEAT", "CLAMP", "MIRROR") else "REPEAT"
        parts.append(
            Part(
                name=p.name,
                positions=np.asarray(p.positions, np.float32),
                normals=np.asarray(p.normals, np.float32),
                indices=np.asarray(p.indices, np.uint32),
                joints=np.asarray(p.joints),
                weights=np.asarray(p.weights, np.float32),
                color=(m.base_color[0], m.base_color[1], m.base_color[2])
                if m is not None
                else (0.6, 0.6, 0.6),
                double_sided=bool(m is not None and m.double_sided),  # (twigs: bark by now)
                uvs=np.asarray(p.uvs, np.float32) if has_uv else None,
                texture=None if tex is None else decoded[id(tex)],
                alpha_cutoff=m.alpha_cutoff if m is not None else None,
                opacity=float(m.base_color[3]) if m is not None and len(m.base_color) > 3 else 1.0,
                wrap=(wrap, wrap),
            )
        )
    return parts


CALIBRATION_TOL = 0.005  # the thinned cards cover the card cells' texels to this share (or
# to a texel); the factor's secant solve (lod_cover.solve_factor) takes 2-4 draws at the
# default atlas, 4-6 at 128-256 px ones, eight bisections took eight
CALIBRATION_STEPS = 6  # secant steps at most, then the factor last tried


def render_views(
    lod: Lod, materials: list[Material], centre: np.ndarray, radius: float, options, cells
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The two atlases (albedo + alpha, normals + depth) of `lod`'s rest pose, and the same
    two of the cards' views side by side at options.card_cell px (finer than the atlas's:
    they are magnified at the switch); `options` an ImpostorOptions, `cells` [(col, row)] the
    cards' cells.

    Beyond max_leaf_cards, every k-th leaf is drawn, enlarged so that the card views cover
    what all the leaves cover there (a few quick draws of the card cells): clumped leaves
    (needles on a shoot, leaflets on a frond) overlap, so keeping their summed area (k×)
    covered up to 47 % more than the tree (the fir) and the impostor popped at its switch."""
    from .drawable import Drawable
    from .impostor_render import AtlasRenderer, leafiness
    from .lod_cover import solve_factor

    texel = 2.0 * radius / options.cell  # a cell holds the bounding sphere
    primitives = _twigs_as_bark(lod.primitives)
    leaves = [np.asarray(p.positions)[:, 2] for p in primitives if p.material != "bark" and len(p.positions)]
    # leafless: nothing widened (widened everywhere, shave grass's cards covered +25 to +47 %)
    crown = min((float(z.min()) for z in leaves), default=-math.inf)
    leaf_area, bark_area = _shown(primitives)
    budget = WIDEN_SHARE * (leaf_area + bark_area)  # shared by the bark primitives
    leafy = leafiness(leaf_area / max(leaf_area + bark_area, 1e-12))
    prims, keep = [], {}
    for i, p in enumerate(primitives):
        wide, drawn, used = _bark_at_least(
            _widest_bark(p, options.max_bark_triangles), MIN_BARK_TEXELS * texel, crown, budget
        )
        prims.append(wide)
        budget = max(budget - used, 0.0)
        if drawn is not None:
            keep[i] = drawn
    thin = [_fewer_leaves(p, options.max_leaf_cards) for p in prims]
    decoded: dict[int, np.ndarray] = {}  # the leaf atlas is decoded once for both part lists
    parts = _atlas_parts(thin, materials, decoded)
    thinned = [_corners(p) if t is not p else 0 for t, p in zip(thin, prims)]
    with AtlasRenderer(centre, radius, options.grid, options.cell, leafy) as r:
        if any(thinned):

            def cover(area: float) -> int:
                scaled = [_enlarged(q, area, t) if t else q for q, t in zip(parts, thinned)]
                r.draw(Drawable(parts=scaled, n_joints=1), cells, keep)
                return r.covered(cells)

            r.draw(Drawable(parts=_atlas_parts(prims, materials, decoded), n_joints=1), cells, keep)
            target = r.covered(cells)
            k = max(len(p.positions) / max(len(t.positions), 1) for p, t in zip(prims, thin))
            # area factor 1 (never more cover) .. 2k, from the summed area k
            tol = max(CALIBRATION_TOL, 1.0 / max(target, 1))  # a small atlas: a texel at least
            area = solve_factor(cover, target, 1.0, 2.0 * k, tol, CALIBRATION_STEPS, start=k)
            parts = [_enlarged(q, area, t) if t else q for q, t in zip(parts, thinned)]
        final = Drawable(parts=parts, n_joints=1)
        r.draw(final, None, keep)
        albedo, normal = r.read()
        card_albedo, card_normal = r.strip(final, cells, keep, options.card_cell)
    return _dilate(albedo, options.cell), normal, _dilate(card_albedo, options.card_cell), card_normal
