"""The impostor: the last LOD, a tree drawn as a few textured cards showing a view atlas's views.

    lod, material = build_impostor(coarse_lod, materials, lod_options, distance, "wind_lod4_loop")
    # Result: a Lod of 2 crossed cards (8 triangles: a face each way) skinned to one joint swaying like the
    # trunk, with `lod.impostor` holding the hemi-octahedral atlas (albedo + alpha, normals +
    # depth) for engines with impostor shaders; `material` ("impostor") samples the cards'
    # strip of two of its views, drawn finer (albedo + alpha, tangent-space normal map).

The atlas (impostor_render.render_atlas, one batched GL pass) holds grid × grid orthographic
views of the bounding sphere (centre, radius), one per cell. Views look at the centre from the
upper hemisphere; a direction d (unit, from the centre towards the viewer, in the frame
a, b, up = generator +X, +Y, +Z) lands in the cell given by the hemi-octahedral encoding:

    s = |d.a| + |d.b| + d.up;  p = (d.a / s, d.b / s)
    (u, v) = ((p.x + p.y) / 2 + 1/2,  (p.y − p.x) / 2 + 1/2)     # v from the image's top
    cell = (floor(u · grid), floor(v · grid))                        # (column, row)

and a cell's centre (u, v) decodes back with p = (u − v, u + v − 1), d = normalize(p.x, p.y,
1 − |p.x| − |p.y|). Inside a cell the view's right = normalize(up × d) and its up' = d × right;
pixel (x, y) ∈ [−1, 1]² (y towards the top of the cell) shows centre + radius·(x·right + y·up').

Cards: the two cells nearest the horizon along +a and +b (elevation about 90°/grid), each a
quad through the centre in its view's plane showing that cell, one face each way: seen from
behind, a card shows the mirror image, the true silhouette from there. The cards sample a
strip of their own views, drawn CARD_SCALE× finer than the atlas's (card_textures), normals in
the cards' tangent space, so engines light them with the crown's own normals. They ride one
joint at the trunk base turning as the trunk does at the crown's height (decimated for the
impostor's distance like any LOD clip), so the tree keeps swaying.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .asset import Impostor, Lod, Material, Primitive, Texture
from .errors import TreegenError
from .impostor_atlas import render_views
from .lod import MAX_DISTANCE, LodOptions, screen_distance
from .lod_decimate import decimate
from .impostor_sway import trunk_sway


CARD_SCALE = 2  # the cards' views have this many times the atlas cells' pixels a side


@dataclass(frozen=True)
class ImpostorOptions:
    """Atlas size and when the impostor takes over.

    switch_px: the tree's height on screen (pixels of the LOD options' view, width / aspect
    high) below which the impostor is used; at 1.5 × cell an atlas texel spans 1.5 pixels
    there, a card's (card_cell) 0.75 (less where min_factor puts the switch farther: 72 px
    with the default LODs). At 1.5 the aspen's, willow's and oak's cards scored IoU 0.90, 0.89,
    0.73 against their LOD3 at the switch, at 0.75 0.92, 0.92, 0.77.
    The switch is never nearer than min_factor × the last geometric LOD's distance.
    distance: metres that replace both (--impostor-distance), beyond the last LOD's; `flag`
    names it in messages as the user gave it (a catalogue's or a layout's key)."""

    grid: int = 16  # views per side of the atlas (engine plug-ins' 16 × 16)
    cell: int = 64  # pixels per view: a 1024 × 1024 atlas
    switch_px: float = 96.0
    min_factor: float = 1.5
    max_leaf_cards: int = 2000  # leaves drawn into the atlas (beyond: fewer, larger, same cover)
    # the widest bark triangles drawn: a cap for huge coarse LODs only (the default coarsest
    # LODs have ≤ 17,000); thin twigs, dropped, lose a bush's cover (−51 % at 8,000 of 11,294)
    max_bark_triangles: int = 40_000
    alpha_cutoff: float = 0.5
    distance: float | None = None
    flag: str = "--impostor-distance"

    @property
    def card_cell(self) -> int:
        return CARD_SCALE * self.cell

    def __post_init__(self) -> None:
        if self.distance is not None and not self.distance <= MAX_DISTANCE:  # (NaN too)
            raise TreegenError(
                f"{self.flag} {self.distance:g}: at most {MAX_DISTANCE:,.0f} m (any tree is under a pixel "
                "long before)"
            )
        if not 2 <= self.grid <= 64 or not 8 <= self.cell <= 512 or self.grid * self.cell > 8192:
            raise TreegenError(
                f"impostor atlas {self.grid}×{self.grid} views of {self.cell} px: "
                "grid in 2..64, cell in 8..512 px, at most 8192 px a side"
            )
        if not (
            self.switch_px > 0
            and self.min_factor >= 1
            and self.max_leaf_cards >= 1
            and self.max_bark_triangles >= 1
            and (self.distance is None or self.distance > 0)
        ):
            raise TreegenError(
                "impostor: switch_px > 0, min_factor >= 1, max_leaf_cards and max_bark_triangles "
                ">= 1, distance > 0 metres"
            )


IMPOSTOR_DEFAULTS = ImpostorOptions()
IMPOSTOR_SIZES = (128, 2048)  # --impostor-size range (atlas side, px): 8 to 128 px a view


def atlas_side(texture_size: int, options: ImpostorOptions = IMPOSTOR_DEFAULTS) -> int:
    """The atlas side `--impostor-size` defaults to: twice the leaf atlas's, so a smaller
    texture budget shrinks the impostor with it (mobile: 512 px, 32 px views), and at most
    the default's 64 px views (1024 px), which already give a texel per 1.5 screen pixels
    where the impostor takes over (switch_px tall); larger views cost CPU and bytes that
    show only nearer than that."""
    return min(max(2 * int(texture_size), IMPOSTOR_SIZES[0]), options.grid * options.cell)


def sized(side: int, options: ImpostorOptions = IMPOSTOR_DEFAULTS) -> ImpostorOptions:
    """`options` with an atlas `side` px wide: the grid stays (engine plug-ins expect 16 × 16),
    the views shrink or grow."""
    return replace(options, cell=side // options.grid)


def placed(side: int, distance: float | None, flag: str, lod: LodOptions) -> ImpostorOptions:
    """The impostor of a tree whose LODs are `lod`: an atlas `side` px wide, used from
    `distance` metres if given (`flag` names it). With the LODs' own metres given
    (--lod-distances), a distance not beyond the last is refused now, before anything grows."""
    options = replace(sized(side), distance=distance, flag=flag)
    if lod.distances:
        check_beyond(options, lod.distances[-1])
    return options


def check_beyond(options: ImpostorOptions, last: float) -> None:
    """Refuse the user's switch `distance` unless it lies beyond the last LOD's, `last` m."""
    if options.distance is not None and not options.distance > last:
        raise TreegenError(
            f"{options.flag} {options.distance:g}: the impostor comes after the last LOD, "
            f"used from {last:.4g} m on this tree; give more than {last:.4g}"
        )


# ------------------------------------------------------------------ hemi-octahedral mapping


def encode(d: np.ndarray) -> np.ndarray:
    """Unit directions (…, 3) in (a, b, up), up ≥ 0 → atlas (u, v) in [0, 1]², v from the top."""
    d = np.asarray(d, np.float64)
    s = np.abs(d[..., 0]) + np.abs(d[..., 1]) + d[..., 2]
    px, py = d[..., 0] / s, d[..., 1] / s
    return np.stack([0.5 * (px + py) + 0.5, 0.5 * (py - px) + 0.5], axis=-1)


def cell_of(d: np.ndarray, grid: int) -> np.ndarray:
    """(column, row) of the cell a direction lands in."""
    return np.clip(np.floor(encode(d) * grid), 0, grid - 1).astype(np.int64)


def cell_direction(col, row, grid: int) -> np.ndarray:
    """Unit direction (…, 3) a cell's centre decodes to (the view rendered into it)."""
    u = (np.asarray(col, np.float64) + 0.5) / grid
    v = (np.asarray(row, np.float64) + 0.5) / grid
    px, py = u - v, u + v - 1.0
    d = np.stack([px, py, 1.0 - np.abs(px) - np.abs(py)], axis=-1)
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def view_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(right, up') of the orthographic view looking at the centre from direction d."""
    right = np.cross((0.0, 0.0, 1.0), d)
    n = np.linalg.norm(right)
    right = right / n if n > 1e-5 else np.array([0.0, 1.0, 0.0])
    return right, np.cross(d, right)


# --------------------------------------------------------------------------------- the atlas


def sphere(lod: Lod) -> tuple[np.ndarray, float, tuple[np.ndarray, np.ndarray]]:
    """Centre (the rest-pose box centre), radius (farthest vertex, +1 %) and box (min, max)
    of a LOD. Coordinates as rows (3, V): numpy reduces a (V, 3) array along its long axis
    some 50× slower (12 ms for the aspen's 90,000 leaf vertices)."""
    pts = np.concatenate([np.asarray(p.positions, np.float32) for p in lod.primitives if len(p.positions)])
    xyz = np.ascontiguousarray(pts.T)
    lo, hi = xyz.min(1).astype(np.float64), xyz.max(1).astype(np.float64)
    centre = 0.5 * (lo + hi)
    d = xyz.astype(np.float64) - centre[:, None]
    radius = float(np.sqrt((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).max())) * 1.01
    return centre, max(radius, 1e-3), (lo, hi)


# --------------------------------------------------------------------------------- the cards

CARD_AXES = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0))  # horizon views along +a and +b


def card_cells(grid: int) -> list[tuple[int, int]]:
    cells = [cell_of(np.array(a) + (0, 0, 1e-6), grid) for a in CARD_AXES]
    return [(int(c[0]), int(c[1])) for c in cells]


def cards(centre: np.ndarray, radius: float, grid: int) -> Primitive:
    """Per card cell, a quad in its view's plane through the centre, twice: one face towards
    each side (seen from behind, a card shows the mirror image, the true silhouette from
    there). UVs (bottom-left origin) on the card's slot of card_textures' strip. Flat normals
    (±the view) and tangents along the view's right: the crown's own normals come from the
    strip's normal map, one map for both faces (see card_textures), so any engine lights the
    cards texel by texel as it lights the geometric LOD's leaves and bark."""
    corners = np.array([(-1, -1), (1, -1), (-1, 1), (1, 1)], np.float64)
    cells = card_cells(grid)
    pos: list[np.ndarray] = []
    nrm: list[np.ndarray] = []
    tan: list[np.ndarray] = []
    uv: list[np.ndarray] = []
    idx: list[np.ndarray] = []
    for i, (col, row) in enumerate(cells):
        d = cell_direction(col, row, grid)
        right, up = view_basis(d)
        offset = corners[:, :1] * right + corners[:, 1:] * up
        u = (i + 0.5 + 0.5 * corners[:, 0]) / len(cells)
        v = 0.5 + 0.5 * corners[:, 1]
        # w · cross(normal, tangent) is up' on both faces: the image's up (glTF's TANGENT)
        for facing, w, tri in ((d, 1.0, (0, 1, 3, 0, 3, 2)), (-d, -1.0, (0, 3, 1, 0, 2, 3))):
            idx.append(np.array(tri) + 4 * len(pos))
            pos.append(centre + radius * offset)
            nrm.append(np.tile(facing, (4, 1)))
            tan.append(np.tile(np.append(right, w), (4, 1)))
            uv.append(np.stack([u, v], 1))
    V = 4 * len(pos)
    return Primitive(
        name="impostor",
        material="impostor",
        positions=np.concatenate(pos).astype(np.float32),
        normals=np.concatenate(nrm).astype(np.float32),
        uvs=np.concatenate(uv).astype(np.float32),
        indices=np.concatenate(idx).astype(np.uint32),
        joints=np.zeros((V, 4), np.uint16),
        weights=np.tile(np.array([1, 0, 0, 0], np.float32), (V, 1)),
        tangents=np.concatenate(tan).astype(np.float32),
    )


FLAT_NORMAL = (128, 128, 255)  # a tangent-space normal map's "no bump" texel
MIN_FACING = 0.05  # a card texel's normal leans at most this close to the card's plane
MASS_FACING = 0.6  # the crown's rounded mass: its normal at a card's middle is the view,
MASS_WEIGHT = 0.45  # at its sides tilted sideways, at its top upwards. Each texel's normal
# is the mean over its NEIGHBOURS² neighbours of their leaf or bark normals (less their part
# along the view; an empty neighbour leans nowhere) plus this much of the mass's: the mass
# says which way the card faces, the neighbours how the crown's surface turns across it. One
# leaf's own normal alone lit leaves turned from the sun as black blotches a texel or two
# wide; with their part along the view (double-sided leaves face the camera that drew them)
# each card faced its own view and, seen at 45°, the card turned to the sun lit its half of
# the crown and the other's went dark, the opposite of the geometric LOD's halves. The
# neighbours' sum (up to 9 or 25 times the mass) let clumps of leaves facing one way lean
# whole patches away from the sun: 6-23 % of the crown's pixels were darker than all but 2 %
# of the coarsest LOD's, black blotches at the switch size (bench/impostor_colour_bench.py's
# dark column). Averaged over the covered neighbours only, a texel or two out at the fringe
# kept its own leaf's lean: black specks along the crown's edge


NEIGHBOURS = 2 * CARD_SCALE + 1  # a card texel's neighbourhood: the atlas's 3 × 3 texels


def _box(a: np.ndarray, k: int = NEIGHBOURS) -> np.ndarray:
    """Sum over each texel's k × k neighbourhood (k odd, zero outside) of an (H, W, C) array."""
    p = np.pad(a, ((k // 2, k // 2), (k // 2, k // 2), (0, 0)))
    rows = np.add.reduce([p[i : i + a.shape[0]] for i in range(k)])
    return np.add.reduce([rows[:, j : j + a.shape[1]] for j in range(k)])


def card_textures(albedo: np.ndarray, normal: np.ndarray, grid: int) -> tuple[np.ndarray, np.ndarray]:
    """The cards' own images from their views side by side (render_views: a square per card),
    so an engine samples a strip a few per cent of the atlas's size (the atlas stays in the
    file for impostor shaders, unsampled). The normals, in the atlas's
    (a, b, up) frame, are turned into each card's tangent space, (n·right, n·up', n·d): the
    front face's frame, and also the back face's, since the back shows the mirror image and
    its normals mirror through the card's plane with it. Background texels are flat."""
    a_strip, n_strip = [], []
    cell = albedo.shape[0]
    for i, (col, row) in enumerate(card_cells(grid)):
        a_cell = albedo[:, i * cell : (i + 1) * cell]
        n = normal[:, i * cell : (i + 1) * cell, :3].astype(np.float64) / 127.5 - 1.0
        d = cell_direction(col, row, grid)
        right, up = view_basis(d)
        x = (np.arange(cell) + 0.5) / cell * 2.0 - 1.0  # texel centres, [-1, 1] across the cell
        y = -x  # rows run down the cell
        mass = MASS_FACING * d + x[None, :, None] * right + (0.5 + 0.5 * y[:, None, None]) * up
        mass /= np.linalg.norm(mass, axis=-1, keepdims=True)
        n = n - (n @ d)[..., None] * d  # the leaves faced this view in the atlas: no more
        covered = (a_cell[..., 3:] > 0).astype(np.float64)
        # the neighbourhood's mean, empty texels counting as no lean (_box(1): the box's size,
        # cut at the cell's border): a few texels out at the crown's fringe are lit as its
        # rounded surface there, not as their one or two leaves (black specks at the edges)
        n = _box(n * covered) / _box(np.ones_like(covered))
        n = n + MASS_WEIGHT * mass  # the crown lit as a rounded mass
        t = np.stack([n @ right, n @ up, n @ d], axis=-1)
        t /= np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-12)
        t[..., 2] = np.maximum(t[..., 2], MIN_FACING)  # then unit again: facing at least that
        t /= np.linalg.norm(t, axis=-1, keepdims=True)
        enc = np.clip(np.rint(127.5 * t + 127.5), 0, 255).astype(np.uint8)
        enc[a_cell[..., 3] == 0] = FLAT_NORMAL
        a_strip.append(a_cell)
        n_strip.append(enc)
    return np.concatenate(a_strip, axis=1), np.concatenate(n_strip, axis=1)


# ----------------------------------------------------------------------------------- the stage


def switch_distance(height: float, last: float, lod_options: LodOptions, options: ImpostorOptions) -> float:
    """Metres from which the tree is at most switch_px tall on screen (and ≥ min_factor × last),
    or the user's `distance`, which must lie beyond the last LOD's."""
    if options.distance is not None:
        check_beyond(options, last)
        return float(options.distance)
    d = screen_distance(height, options.switch_px, lod_options, of=lod_options.width / lod_options.aspect)
    return float(max(d, options.min_factor * last, 1e-3))


def atlas_source(coarse: Lod) -> Lod:
    """What the atlas draws: the coarsest geometric LOD, the tree the impostor takes over from,
    so the switch shows the same crown. (LOD0's leaves thinned to 600 cards of their summed
    area on the coarse LOD's widest bark, as before, changed the crown's cover at the switch by
    −64 % (the desert bush, its thin stems dropped) to +47 % (the fir, its clumped needles
    spread out).)"""
    return replace(coarse, clips=[])


def build_impostor(
    coarse: Lod,
    materials: list[Material],
    lod_options: LodOptions,
    distance: float,
    clip_name: str,
    options: ImpostorOptions = IMPOSTOR_DEFAULTS,
) -> tuple[Lod, Material]:
    """The impostor LOD (cards + atlas) of a tree whose coarsest geometric LOD is `coarse` (it
    is drawn into the atlas; its skeleton and clip give the sway), used from `distance`."""
    source = atlas_source(coarse)
    centre, radius, (lo, hi) = sphere(source)
    albedo, normal, card_albedo, card_normal = render_views(
        source, materials, centre, radius, options, card_cells(options.grid)
    )
    from concurrent.futures import ThreadPoolExecutor

    from .texture_png import png_bytes, png_bytes_unfiltered as png

    with ThreadPoolExecutor(1) as pool:  # zlib lets go of the GIL: one atlas on each core
        normal_png = pool.submit(png, normal)
        albedo_tex = Texture("impostor_albedo", png(albedo), wrap="CLAMP")
        card_albedo, card_normal = card_textures(card_albedo, card_normal, options.grid)
        normal_tex = Texture("impostor_normal", normal_png.result(), wrap="CLAMP", srgb=False)
    cards_tex = Texture("impostor_cards", png_bytes(card_albedo), wrap="CLAMP")
    cards_normal = Texture("impostor_cards_normal", png_bytes(card_normal), wrap="CLAMP", srgb=False)
    prim = cards(centre, radius, options.grid)
    skel, dense = trunk_sway(coarse, float(centre[2]))
    clips = [] if dense is None else [decimate(skel, [prim], dense, distance, lod_options, clip_name)[0]]
    imp = Impostor(
        albedo=albedo_tex,
        normal_depth=normal_tex,
        grid=options.grid,
        cell=options.cell,
        centre=centre,
        radius=radius,
        bounds=(lo, hi),
        cards=tuple(card_cells(options.grid)),
        alpha_cutoff=options.alpha_cutoff,
    )
    material = Material(
        name="impostor",
        base_color=(1.0, 1.0, 1.0, 1.0),
        roughness=0.95,
        alpha_cutoff=options.alpha_cutoff,
        base_texture=cards_tex,
        normal_texture=cards_normal,
    )
    return Lod(
        primitives=[prim], skeleton=skel, clips=clips, distance=distance, screen_coverage=0.0, impostor=imp
    ), material
