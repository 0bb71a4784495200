"""The leaf atlas: a species' leaf variants side by side in one RGBA image, each blade drawn
from the same LeafShape outline mesh.py stamps (leafshapes.py), with veins, mottling and a
darker rim, so the alpha-tested blade on a card matches `Tree.leaf_area`."""

from __future__ import annotations

import colorsys
import math
from dataclasses import dataclass

import numpy as np

from .leafshapes import outline
from .texture_color import check_color, smoothstep, to_srgb8


def _jitter(color, dh: float, ds: float, dv: float) -> np.ndarray:
    """Shift a linear colour's hue/saturation/value (HSV done on the linear values: small moves)."""
    h, s, v = colorsys.rgb_to_hsv(*(float(c) for c in color))
    rgb = colorsys.hsv_to_rgb(
        (h + dh) % 1.0, min(max(s * (1 + ds), 0.0), 1.0), min(max(v * (1 + dv), 0.0), 1.0)
    )
    return np.array(rgb, dtype=np.float32)


def _value_noise(rng: np.random.Generator, h: int, w: int, cells: int) -> np.ndarray:
    """Smooth noise in −1..1: a random `cells`² grid, smoothly upsampled (mottling, not tiled)."""
    g = rng.uniform(-1.0, 1.0, (cells + 1, cells + 1)).astype(np.float32)

    def weights(m: int):
        p = np.linspace(0.0, cells, m, dtype=np.float32)
        i = np.minimum(p.astype(np.int32), cells - 1)
        f = p - i
        return i, f * f * (3 - 2 * f)  # smoothstep: no grid creases

    iy, fy = weights(h)
    ix, fx = weights(w)
    rows = g[:, ix] * (1 - fx) + g[:, ix + 1] * fx  # (cells + 1, w), cheap
    return rows[iy] * (1 - fy)[:, None] + rows[iy + 1] * fy[:, None]


@dataclass(frozen=True, eq=False)
class LeafAtlas:
    """Leaf variants side by side in one RGBA image.

    `rects[k]` = (u0, v0, u1, v1) is variant k's card rectangle in glTF UVs (origin top-left,
    v down). The blade is drawn tip-up: the card's base (v_card = 0) lies on the rectangle's
    bottom edge v1, its tip (v_card = 1) on the top edge v0, and card u = x + 0.5 runs u0 → u1,
    so the image shows the blade as seen from its front (+normal) side. Use `card_uvs`.
    """

    rgba: np.ndarray  # uint8 (H, W, 4): sRGB colour, straight alpha = blade coverage
    rects: np.ndarray  # float32 (variants, 4): u0, v0, u1, v1
    shape: int  # the LeafShape code drawn

    @property
    def variants(self) -> int:
        return len(self.rects)


def card_uvs(
    card_uv01: np.ndarray, variant: np.ndarray, atlas: LeafAtlas, origin: str = "top-left"
) -> np.ndarray:
    """Map card UVs (u = x + 0.5, v = y, base at v = 0) into each vertex's variant cell.

    `origin="top-left"` gives glTF UVs (as `atlas.rects`). Asset Primitive.uvs use the
    bottom-left origin (OpenGL/USD; exchange/gltf_mesh.py writes 1 − v): pass
    `origin="bottom-left"` for those, and both writers then sample the same texels.
    """
    if origin not in ("top-left", "bottom-left"):
        raise ValueError(f"origin must be 'top-left' or 'bottom-left', got {origin!r}")
    uv = np.asarray(card_uv01, dtype=np.float64)
    r = atlas.rects.astype(np.float64)[np.asarray(variant, dtype=np.int64)]
    out = np.empty(uv.shape, dtype=np.float32)
    out[:, 0] = r[:, 0] + uv[:, 0] * (r[:, 2] - r[:, 0])
    v = r[:, 3] - uv[:, 1] * (r[:, 3] - r[:, 1])
    out[:, 1] = v if origin == "top-left" else 1.0 - v
    return out


def _grid(variants: int, size: int):
    """Columns × rows for the cells (near square), cell size in texels and padding."""
    cols = math.ceil(math.sqrt(variants))
    rows = math.ceil(variants / cols)
    cw, ch = size // cols, size // rows
    pad = max(2, min(cw, ch) // 32)  # texels kept clear round each card (mip bleeding)
    if min(cw, ch) - 2 * pad < 8:
        raise ValueError(f"leaf atlas {size}² is too small for {variants} variants")
    return cols, rows, cw, ch, pad


def atlas_rects(variants: int, size: int) -> np.ndarray:
    """The card rectangles (LeafAtlas.rects) of a `variants`-leaf atlas of side `size`, without
    drawing it: a mesh can be UV-mapped while the pixels are still being made."""
    cols, _rows, cw, ch, pad = _grid(variants, size)
    r, c = np.divmod(np.arange(variants), cols)
    x0, y0 = c * cw + pad, r * ch + pad
    return (np.stack([x0, y0, x0 + cw - 2 * pad, y0 + ch - 2 * pad], axis=1) / size).astype(np.float32)


def _coverage(shape: int, bw: int, bh: int):
    """Anti-aliased blade coverage over a bh × bw card, tip at row 0.

    Centre samples say inside/outside; texels within a texel of the outline get coverage
    0.5 ± distance to the outline (a signed-distance ramp), so edges are smooth without
    supersampling. The outline is the union's boundary: edges used by exactly one triangle
    (matched by coordinates, so the palm's two halves share their midrib).
    """
    o = outline(shape)
    p2 = o.uvs  # (u, v) = (x + 0.5, y)
    px = np.column_stack([p2[:, 0] * bw, (1.0 - p2[:, 1]) * bh])  # texel units, y down
    tri = px[o.triangles]  # (T, 3, 2)
    ys, xs = np.mgrid[0:bh, 0:bw].astype(np.float64) + 0.5
    inside = np.zeros((bh, bw), dtype=bool)
    for a, b, c in tri:  # ≤ 12 triangles, whole-image ops
        area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        if abs(area) < 1e-12:
            continue
        sgn = 1.0 if area > 0 else -1.0
        e = np.ones((bh, bw), dtype=bool)
        for p, q in ((a, b), (b, c), (c, a)):
            e &= sgn * ((q[0] - p[0]) * (ys - p[1]) - (q[1] - p[1]) * (xs - p[0])) >= 0
        inside |= e
    # Boundary edges of the union, by rounded endpoint coordinates.
    count: dict[tuple, int] = {}
    seg: dict[tuple, tuple] = {}
    for t in o.triangles:
        for i, j in ((0, 1), (1, 2), (2, 0)):
            pa, pb = tuple(np.round(p2[t[i]], 9)), tuple(np.round(p2[t[j]], 9))
            key = (min(pa, pb), max(pa, pb))
            if pa == pb:
                continue
            count[key] = count.get(key, 0) + 1
            seg[key] = (px[t[i]], px[t[j]])
    edges = np.array([seg[k] for k, n in count.items() if n == 1])  # (E, 2, 2)
    # Only texels next to an inside/outside change can be partly covered.
    m = np.pad(inside, 1, mode="constant")
    grow = m[1:-1, 1:-1].copy()
    shrink = grow.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            nb = m[1 + dy : 1 + dy + bh, 1 + dx : 1 + dx + bw]
            grow |= nb
            shrink &= nb
    band = np.flatnonzero((grow & ~shrink).ravel())
    alpha = inside.astype(np.float32)
    if band.size and edges.size:
        q = np.column_stack([xs.ravel()[band], ys.ravel()[band]])  # (B, 2)
        a, d = edges[:, 0], edges[:, 1] - edges[:, 0]  # (E, 2)
        rel = q[:, None, :] - a[None, :, :]  # (B, E, 2)
        t = np.clip((rel * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-12), 0.0, 1.0)
        dist = np.sqrt(((rel - t[..., None] * d) ** 2).sum(-1)).min(axis=1)
        sign = np.where(inside.ravel()[band], 1.0, -1.0)
        alpha.ravel()[band] = np.clip(0.5 + sign * dist, 0.0, 1.0)
    return alpha, inside


def _lobes(shape: int, aspect: float):
    """Primary veins as (origin, unit direction, length) in physical blade units.

    Physical units: X = x · aspect (width / length), Y = y, so vein angles and widths look
    right on the stretched card. Pinnate blades have one midrib base → tip; the star is
    palmate, one primary vein from its centre to each lobe tip plus the petiole stub.
    """
    if shape == 7:
        o = outline(7)
        c = np.array([0.0, 0.5])
        tips = o.uvs[1::2] - [0.5, 0.0]  # outer ring points (even k)
        out = []
        for tx, ty in tips:
            d = np.array([tx * aspect, ty]) - c
            ln = float(np.hypot(*d))
            out.append((c, d / ln, ln))
        out.append((np.array([0.0, 0.0]), np.array([0.0, 1.0]), 0.5))
        return out
    return [(np.array([0.0, 0.0]), np.array([0.0, 1.0]), 1.0)]


def _veins(X: np.ndarray, Y: np.ndarray, lobes, rng, side_veins: bool, half_width: float):
    """(midrib, side veins, interveinal relief), each 0..1, at physical coords (X, Y).

    Pinnate side veins leave the midrib at alternate heights and curve toward the tip; blades
    narrower than a quarter of their length (willow, grass, palm straps) get parallel veins
    converging at base and tip instead. Jitter per variant comes from `rng`.
    """
    spacing = rng.uniform(0.10, 0.135)
    slope = rng.uniform(0.7, 1.0)  # how far a side vein climbs per unit outward
    bend = rng.uniform(0.6, 0.75)  # < 1: veins curve toward the tip near the margin
    phase = rng.uniform(0.0, 1.0, 2)  # left / right rows offset (alternate veins)
    best = None
    for origin, d, ln in lobes:
        rx, ry = X - origin[0], Y - origin[1]
        along = rx * d[0] + ry * d[1]
        across = rx * d[1] - ry * d[0]
        # Angular closeness picks the lobe a texel belongs to (a single lobe wins everywhere).
        score = along / np.maximum(np.hypot(rx, ry), 1e-6) if len(lobes) > 1 else None
        if best is None:
            best = [score, along / ln, across, ln]
        else:
            take = score > best[0]
            best[0] = np.where(take, score, best[0])
            best[1] = np.where(take, along / ln, best[1])
            best[2] = np.where(take, across, best[2])
            best[3] = np.where(take, ln, best[3])
    _, s, across, ln = best
    a = np.abs(across)
    sc = np.clip(s, 0.0, 1.0)
    inside_len = smoothstep(-0.03, 0.0, s) * (1.0 - smoothstep(0.97, 1.0, s))
    w_mid = np.minimum(0.010 * (1.0 - 0.7 * sc) * np.sqrt(ln) + 0.002, 0.09 * half_width)
    mid = (1.0 - smoothstep(0.0, 1.0, a / w_mid)) * inside_len
    zero = np.zeros_like(mid)
    if not side_veins:
        return mid, zero, zero
    if half_width < 0.125:  # narrow blade: parallel veins
        taper = np.power(np.sin(np.pi * sc), 0.5) * half_width + 1e-6
        k = a / taper * 3.5  # three veins a side, at k = 1, 2, 3
        dist = np.abs(k - np.clip(np.round(k), 1, 3)) * taper / 3.5
        w = 0.35 * half_width / 3.5
        side = (1.0 - smoothstep(0.0, 1.0, dist / w)) * inside_len
        relief = 1.0 - np.abs(2.0 * (k - np.floor(k)) - 1.0)
        return mid, side * 0.7, relief * 0.5
    t = (s * ln - slope * np.power(a + 1e-6, bend)) / spacing
    t = t + np.where(across < 0, phase[0], phase[1])
    frac = np.abs(t - np.round(t))  # 0 on a vein, 0.5 between two
    dist = frac * spacing / math.sqrt(1.0 + slope * slope)
    w_side = 0.004 * (1.0 - 0.6 * np.clip(a / (2 * half_width), 0, 1)) + 0.0015
    side = 1.0 - smoothstep(0.0, 1.0, dist / w_side)
    along_ok = smoothstep(0.03, 0.10, s) * (1.0 - smoothstep(0.85, 0.98, s))
    side *= along_ok * smoothstep(0.0, 1.5, a / w_mid)  # starts at the midrib's edge
    relief = smoothstep(0.0, 0.5, frac) * along_ok
    return mid, side, relief


def leaf_atlas(
    shape: int, color, size: int = 512, variants: int = 4, seed: int = 0, aspect: float = 0.5
) -> LeafAtlas:
    """RGBA atlas of `variants` leaves drawn from LeafShape `shape`'s outline.

    `color` is the blade's mean linear RGB; `aspect` is the card's width / length
    (Params.leaf_scale_x) so veins keep their angles on the stretched card. Each variant gets
    its own hue/value jitter, vein spacing and mottling; the blade coverage is the same
    outline in every cell (alpha mean over a card ≈ fill_factor(shape)).
    """
    base = check_color("color", color)
    if variants < 1:
        raise ValueError("variants must be at least 1")
    if not aspect > 0:
        raise ValueError("aspect must be positive")
    outline(shape)  # validates the code
    rng = np.random.default_rng([int(seed), 0x1EAF, int(shape)])
    cols, rows, cw, ch, pad = _grid(variants, size)
    bw, bh = cw - 2 * pad, ch - 2 * pad
    alpha, inside = _coverage(shape, bw, bh)

    # Nearest solid blade texel for every cell texel (colour dilation): one EDT for all cells,
    # kept as a flat index into the blade rectangle.
    cell_inside = np.zeros((ch, cw), dtype=bool)
    cell_inside[pad : pad + bh, pad : pad + bw] = inside
    if not cell_inside.any():
        cell_inside[pad + bh // 2, pad + bw // 2] = True
    from scipy import ndimage  # (0.2 s to import: only where used)

    _, (ny, nx) = ndimage.distance_transform_edt(~cell_inside, return_indices=True)
    nearest = ((ny - pad) * bw + (nx - pad)).ravel()
    # Texels from the margin, counted up to the rim width by repeated 4-neighbour erosion.
    rim_w = max(1.5, 0.012 * bh)
    margin = np.zeros((bh, bw), dtype=np.float32)
    core = np.pad(inside, 1)
    for _ in range(math.ceil(rim_w)):
        margin += core[1:-1, 1:-1]
        core[1:-1, 1:-1] = (
            core[1:-1, 1:-1] & core[:-2, 1:-1] & core[2:, 1:-1] & core[1:-1, :-2] & core[1:-1, 2:]
        )

    # Physical blade coordinates of card texel centres (tip at row 0).
    x = (np.arange(bw, dtype=np.float32) + 0.5) / bw - 0.5
    y = 1.0 - (np.arange(bh, dtype=np.float32) + 0.5) / bh
    X, Y = np.meshgrid(x * np.float32(aspect), y)
    lobes = _lobes(shape, aspect)
    # A darker rim of ~1 % of the length; lighter toward the base and along the midrib.
    rim = 1.0 - 0.22 * (1.0 - smoothstep(0.0, rim_w, margin))
    if shape == 5:
        # A seed / berry / knot: fake a lit sphere instead of veins.
        rr = np.hypot(x[None, :] * 2, (y[:, None] - 0.5) * 2)
        nz = np.sqrt(np.clip(1.0 - rr * rr, 0.0, 1.0))
        lit = np.clip(nz * 0.75 - x[None, :] * 0.45 + (y[:, None] - 0.5) * 0.45, 0.0, 1.0)
        shade0 = (0.5 + 0.6 * lit + 0.3 * lit**6).astype(np.float32)
    else:
        across = 1.0 - np.clip(np.abs(X) / np.float32(0.5 * aspect), 0.0, 1.0)
        shade0 = (1.0 + 0.10 * (0.5 - Y) + 0.08 * across).astype(np.float32)
    side_ok = shape not in (1, 5)
    vein_col = np.array([1.35, 1.30, 0.85], dtype=np.float32)  # pale yellow-green

    rgba = np.zeros((size, size, 4), dtype=np.uint8)
    rects = atlas_rects(variants, size)
    alpha8 = np.round(alpha * 255.0).astype(np.uint8)
    lins = []
    for k in range(variants):
        dh, ds, dv = rng.uniform(-0.025, 0.025), rng.uniform(-0.12, 0.12), rng.uniform(-0.12, 0.12)
        tone = _jitter(base, dh, ds, dv)
        mott = _value_noise(rng, bh, bw, 5) + _value_noise(rng, bh, bw, 13)
        if shape == 5:
            shade = shade0 * (1.0 + 0.05 * mott)
            v = None
        else:
            mid, side, relief = _veins(X, Y, lobes, rng, side_ok, 0.5 * aspect)
            # Mottling, and the blade puffs up a little between side veins.
            shade = shade0 + 0.045 * mott + 0.07 * (relief - 0.5)
            v = np.maximum(mid, side * np.float32(0.8))
        shade *= rim
        lin = shade[..., None] * tone
        if v is not None:
            lin += (tone * vein_col - lin) * v[..., None]
        lins.append(lin)
    # Scale so the mean blade colour over all variants is `color` exactly: a material that
    # swaps its colour factor for this texture keeps the tree's average colour.
    weight = inside.ravel().astype(np.float32)
    total = sum(lin.reshape(-1, 3).T @ weight for lin in lins)
    mean = total / (weight.sum() * len(lins)) if inside.any() else base
    gain = (base / np.maximum(mean, 1e-6)).astype(np.float32)
    for k, lin in enumerate(lins):
        r, c = divmod(k, cols)
        blade = to_srgb8(lin * gain).reshape(-1, 3)
        y0, x0 = r * ch, c * cw
        # Solid texels are their own nearest; the rest take the nearest solid texel's colour.
        rgba[y0 : y0 + ch, x0 : x0 + cw, :3] = blade.take(nearest, axis=0).reshape(ch, cw, 3)
        rgba[y0 + pad : y0 + pad + bh, x0 + pad : x0 + pad + bw, 3] = alpha8
    # Unused cells and texels outside every cell (size not a multiple of the grid) get leaf
    # colour too, alpha 0, so nothing dark bleeds in at small mip levels.
    for k in range(variants, rows * cols):
        r, c = divmod(k, cols)
        rgba[r * ch : (r + 1) * ch, c * cw : (c + 1) * cw, :3] = rgba[:ch, :cw, :3]
    if rows * ch < size:
        rgba[rows * ch :, :, :3] = rgba[rows * ch - 1 : rows * ch, :, :3]
    if cols * cw < size:
        rgba[:, cols * cw :, :3] = rgba[:, cols * cw - 1 : cols * cw, :3]
    return LeafAtlas(rgba=rgba, rects=rects, shape=int(shape))
