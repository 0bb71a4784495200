"""Generated, deterministic textures: a leaf atlas with alpha and tileable bark albedo + normal.

Why: untextured cards read as confetti in an engine. These images are small enough to embed in
every GLB/USD and are drawn from the same LeafShape outlines mesh.py stamps (leafshapes.py), so
the alpha-tested blade on a card matches `Tree.leaf_area` (card area × fill_factor).

Conventions (the glTF ones, so a writer embeds the arrays unchanged):
* UV origin is the top-left of the image, u right, v down (glTF TEXCOORD_0; image row = v·H).
  treegen's own Primitive.uvs have the bottom-left origin (OpenGL/USD) and the glTF writer
  flips them; `card_uvs(..., origin="bottom-left")` gives UVs in that convention.
* Colours passed in are LINEAR RGB (like glTF baseColorFactor / asset.Material.base_color); the
  colour images are sRGB-encoded, as glTF's baseColorTexture requires. A material using them
  should set its base colour factor to white: the mean (in linear light) of the blade texels,
  and of the whole bark albedo, is the colour given, so the tree's average colour is kept.
* Leaf atlas alpha is straight (not premultiplied) coverage; transparent texels carry the colour
  of the nearest solid blade texel so bilinear/mip filtering does not bleed dark halos.
* Normal maps are tangent space, OpenGL/glTF convention: R = +X (u right), G = +Y (up in the
  image, i.e. −v), B = +Z out of the surface; byte = round((n + 1) / 2 · 255).
* Every random choice comes from a numpy Generator seeded from `seed`: same arguments, same
  pixels, and `png_bytes` turns the same pixels into the same bytes.

Default sizes keep a tree's textures to a few hundred KB of PNG: a 512² leaf atlas (four
240-texel leaves) and 256² bark (bark is noise-like and compresses poorly: 512² bark albedo +
normal is ~600 KB, 256² ~190 KB; it tiles around and along every stem anyway).
"""

from __future__ import annotations

import colorsys
import io
import math
import zlib
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from .leafshapes import outline

PNG_COMPRESS_LEVEL = 6  # fixed: PNG bytes are a function of the pixels only
# zlib's run-length strategy: 4× faster than the default on these images (0.03 s instead of
# 0.10 s for a 512² atlas + 256² bark maps) for 12 % more bytes (358 KB instead of 320 KB), which
# keeps `treegen make` within its time budget.
PNG_STRATEGY = zlib.Z_RLE


# ---------------------------------------------------------------------------------- colour

_SRGB_LUT = np.round(
    255.0
    * np.where(
        np.linspace(0.0, 1.0, 4096) <= 0.0031308,
        12.92 * np.linspace(0.0, 1.0, 4096),
        1.055 * np.power(np.linspace(0.0, 1.0, 4096), 1 / 2.4) - 0.055,
    )
).astype(np.uint8)


def _to_srgb8(lin: np.ndarray) -> np.ndarray:
    """Linear 0..1 floats → sRGB-encoded uint8 through a 4096-entry table (fast, exact enough)."""
    idx = np.clip(lin, 0.0, 1.0).astype(np.float32)
    idx *= np.float32(4095.0)
    idx += np.float32(0.5)
    return _SRGB_LUT.take(idx.astype(np.int32))


def srgb8_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB uint8 → linear float64 0..1 (what a renderer samples from the colour images)."""
    x = np.asarray(c, dtype=np.float64) / 255.0
    return np.where(x <= 0.04045, x / 12.92, np.power((x + 0.055) / 1.055, 2.4))


def _jitter(color, dh: float, ds: float, dv: float) -> np.ndarray:
    """Shift a linear colour's hue/saturation/value (HSV done on the linear values: small moves)."""
    h, s, v = colorsys.rgb_to_hsv(*(float(c) for c in color))
    rgb = colorsys.hsv_to_rgb(
        (h + dh) % 1.0, min(max(s * (1 + ds), 0.0), 1.0), min(max(v * (1 + dv), 0.0), 1.0)
    )
    return np.array(rgb, dtype=np.float32)


def _check_color(name: str, color) -> np.ndarray:
    c = np.asarray(color, dtype=np.float64)
    if c.shape != (3,) or not np.all(np.isfinite(c)) or c.min() < 0 or c.max() > 1:
        raise ValueError(f"{name} must be 3 linear floats in 0..1, got {color!r}")
    return c


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


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    """0 below e0, 1 above e1, a C¹ ramp between (float32 in, float32 out, few temporaries)."""
    t = np.subtract(x, np.float32(e0), dtype=np.float32)
    t *= np.float32(1.0 / (e1 - e0))
    np.clip(t, 0.0, 1.0, out=t)
    return t * t * (np.float32(3.0) - np.float32(2.0) * t)


# ---------------------------------------------------------------------------------- leaves


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
    inside_len = _smoothstep(-0.03, 0.0, s) * (1.0 - _smoothstep(0.97, 1.0, s))
    w_mid = np.minimum(0.010 * (1.0 - 0.7 * sc) * np.sqrt(ln) + 0.002, 0.09 * half_width)
    mid = (1.0 - _smoothstep(0.0, 1.0, a / w_mid)) * inside_len
    zero = np.zeros_like(mid)
    if not side_veins:
        return mid, zero, zero
    if half_width < 0.125:  # narrow blade: parallel veins
        taper = np.power(np.sin(np.pi * sc), 0.5) * half_width + 1e-6
        k = a / taper * 3.5  # three veins a side, at k = 1, 2, 3
        dist = np.abs(k - np.clip(np.round(k), 1, 3)) * taper / 3.5
        w = 0.35 * half_width / 3.5
        side = (1.0 - _smoothstep(0.0, 1.0, dist / w)) * inside_len
        relief = 1.0 - np.abs(2.0 * (k - np.floor(k)) - 1.0)
        return mid, side * 0.7, relief * 0.5
    t = (s * ln - slope * np.power(a + 1e-6, bend)) / spacing
    t = t + np.where(across < 0, phase[0], phase[1])
    frac = np.abs(t - np.round(t))  # 0 on a vein, 0.5 between two
    dist = frac * spacing / math.sqrt(1.0 + slope * slope)
    w_side = 0.004 * (1.0 - 0.6 * np.clip(a / (2 * half_width), 0, 1)) + 0.0015
    side = 1.0 - _smoothstep(0.0, 1.0, dist / w_side)
    along_ok = _smoothstep(0.03, 0.10, s) * (1.0 - _smoothstep(0.85, 0.98, s))
    side *= along_ok * _smoothstep(0.0, 1.5, a / w_mid)  # starts at the midrib's edge
    relief = _smoothstep(0.0, 0.5, frac) * along_ok
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
    base = _check_color("color", color)
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
    rim = 1.0 - 0.22 * (1.0 - _smoothstep(0.0, rim_w, margin))
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
        blade = _to_srgb8(lin * gain).reshape(-1, 3)
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


# ---------------------------------------------------------------------------------- bark


def _torus_noise(rng: np.random.Generator, n: int, sx: float, sy: float, count: int = 1) -> np.ndarray:
    """`count` periodic Gaussian fields on an n × n torus, unit variance each (float32).

    Random Fourier coefficients × a Gaussian envelope of widths sx (cycles per tile across, u)
    and sy (cycles along, v). Only whole-cycle frequencies exist, so every field tiles exactly.
    Coefficients are drawn only where the envelope matters (≤ 3.5 widths): fast, and a field
    is the same picture at every `n` that resolves it (256 and 512 agree). The inverse
    transform runs column pass first on the few non-zero columns only.
    """
    kx = int(min(math.ceil(3.5 * sx), n // 2))
    ky = int(min(math.ceil(3.5 * sy), n // 2 - 1))
    fy = np.concatenate([np.arange(0, ky + 1), np.arange(-ky, 0)])[:, None]
    fx = np.arange(0, kx + 1)[None, :]
    env = np.exp(-0.5 * ((fx / sx) ** 2 + (fy / sy) ** 2))
    env[0, 0] = 0.0  # zero mean
    shape = (count, 2 * ky + 1, kx + 1)
    coef = (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)) * env
    cols = np.zeros((count, n, kx + 1), dtype=np.complex64)
    cols[:, : ky + 1] = coef[:, : ky + 1]
    cols[:, n - ky :] = coef[:, ky + 1 :]
    f = np.fft.irfft(np.fft.ifft(cols, axis=1), n=n, axis=2).astype(np.float32, copy=False)
    step = max(1, n // 128)  # the std of a 128² subgrid is plenty
    f /= f[:, ::step, ::step].std(axis=(1, 2), keepdims=True) + np.float32(1e-12)
    return f


def _upsample_periodic(a: np.ndarray, f: int) -> np.ndarray:
    """Bilinear ×f upsampling on the torus (wraps at every edge, so tiling survives)."""
    if f == 1:
        return a
    m = a.shape[0]
    pos = (np.arange(m * f, dtype=np.float32) + 0.5) / f - 0.5
    i0 = np.floor(pos).astype(np.int32)
    t = (pos - i0).astype(np.float32)
    i0 %= m
    i1 = (i0 + 1) % m
    rows = a[i0] * (1 - t)[:, None] + a[i1] * t[:, None]
    return rows[:, i0] * (1 - t)[None, :] + rows[:, i1] * t[None, :]


def _worley_border(rng: np.random.Generator, n: int, gx: int, gy: int, wx: np.ndarray, wy: np.ndarray):
    """Distance in texels to the nearest cell border of a periodic Voronoi diagram, and each
    texel's cell id, for `gx` × `gy` jittered seeds per tile (gy < gx: cells long along v),
    looked up at warped texel coordinates (wx, wy in tile units).
    """
    sx = rng.uniform(0.05, 0.95, gy * gx).astype(np.float32)
    sy = rng.uniform(0.0, 1.0, gy * gx).astype(np.float32)
    ox, oy = rng.uniform(0.0, 1.0, 2).astype(np.float32)  # the seam need not be a grid line
    grid = (np.arange(n, dtype=np.float32) + 0.5) / n
    px = (grid[None, :] + wx) * gx + ox  # cell widths across
    py = (grid[:, None] + wy) * gy + oy  # cell heights along
    cx, cy = np.floor(px).astype(np.int32), np.floor(py).astype(np.int32)
    fx, fy = px - cx, py - cy
    f1 = np.full((n, n), np.inf, dtype=np.float32)
    f2 = np.full((n, n), np.inf, dtype=np.float32)
    ident = np.zeros((n, n), dtype=np.int32)
    cols = [(cx + dx) % gx for dx in (-1, 0, 1)]
    for dy in (-1, 0, 1):  # isotropic in cell units: 3 × 3 suffice
        row = ((cy + dy) % gy) * gx
        for dx, col in zip((-1, 0, 1), cols):
            k = row + col
            ddx = sx.take(k) - fx + dx
            ddy = sy.take(k) - fy + dy
            d = ddx * ddx + ddy * ddy  # squared: order is all that matters here
            np.copyto(ident, k, where=d < f1)
            np.minimum(f2, np.maximum(f1, d), out=f2)
            np.minimum(f1, d, out=f1)
    # F2 − F1 in cell units is stretched with the cells; divided by its own gradient (periodic
    # differences, in texels) it becomes the distance to the border in texels, the same
    # across a furrow whichever way the furrow runs.
    b = np.sqrt(f2) - np.sqrt(f1)
    gxd = np.roll(b, -1, axis=1) - np.roll(b, 1, axis=1)
    gyd = np.roll(b, -1, axis=0) - np.roll(b, 1, axis=0)
    grad = 0.5 * np.sqrt(gxd * gxd + gyd * gyd)
    return b / np.maximum(grad, np.float32(0.5 / n * min(gx, gy))), ident


def bark_height(size: int = 256, seed: int = 0, furrow: float = 1.0) -> np.ndarray:
    """Tileable bark height 0..1 (float32 size × size): long plates split by furrows.

    The plates are cells of a Voronoi diagram on the torus, stretched along v (the stem) and
    bent by smooth periodic warps, so furrows meander, fork and rejoin as on oak, ash or
    cottonwood bark. Furrow width varies along each furrow; plates get their own height,
    flat tops, shallow cross checks and fibres along the stem. `furrow` < 1 blends toward
    smooth bark (aspen, young stems, grass culms): fibres and dark horizontal lenticels only.
    """
    if size < 16:
        raise ValueError("bark texture size must be at least 16")
    if not 0.0 <= furrow <= 1.0:
        raise ValueError(f"furrow must be in 0..1, got {furrow!r}")
    # One independent stream per ingredient: a field clamped at a small `n` (fewer
    # coefficients drawn) must not shift the others, so every size shows the same bark.
    rw, rr, rc, re, rv = (
        np.random.default_rng(s) for s in np.random.SeedSequence([int(seed), 0xBA4C]).spawn(5)
    )
    n = size
    w = _torus_noise(rw, n, 3.0, 2.0, 2)  # big bends of the plates
    rough = _torus_noise(rr, n, 24.0, 8.0, 1)[0]  # ragged furrow edges, plate undulation
    c = _torus_noise(rc, n, 2.0, 14.0, 2)  # cross checks, and where they show
    e = _torus_noise(re, n, 70.0, 12.0, 1)[0]  # fibres along the stem
    cross = (1.0 - _smoothstep(0.0, 0.10, np.abs(c[0]))) * _smoothstep(0.8, 1.6, c[1])
    lenticel = (1.0 - _smoothstep(0.0, 0.22, np.abs(c[0]))) * _smoothstep(0.4, 1.4, c[1])
    smooth = 0.85 + 0.05 * rough + 0.025 * e - 0.7 * lenticel
    if furrow == 0.0:
        return np.clip(smooth, 0.0, 1.0).astype(np.float32)
    # The Voronoi pass is the costly part: it runs at half resolution and is upsampled
    # (the border distance is continuous; plate ids only change inside furrows, unseen).
    f = 2 if n >= 512 and n % 2 == 0 else 1
    m = n // f
    border, ident = _worley_border(
        rv, m, 9, 3, 0.02 * w[0, ::f, ::f] + 0.004 * rough[::f, ::f], 0.03 * w[1, ::f, ::f]
    )
    plate_h = rv.uniform(0.0, 1.0, 27).astype(np.float32)[ident]
    border = _upsample_periodic(border, f)
    plate_h = plate_h.repeat(f, axis=0).repeat(f, axis=1)  # steps fall inside furrows
    border = border * np.float32(f / n)  # texels → tile units
    # Furrows open and close along their length; never under 2.5 texels of the Voronoi pass,
    # or they break up into beads where a thin furrow falls between its samples.
    width = np.maximum(0.012 + 0.008 * np.clip(w[1], -1.0, 1.5), np.float32(2.5 * f / n))
    wall = _smoothstep(0.0, 1.0, border / width)
    crown = _smoothstep(0.0, 1.0, border / (5.0 * width))
    h = wall * (0.50 + 0.22 * crown + 0.12 * plate_h + 0.06 * rough - 0.15 * cross) + 0.035 * e
    h -= h.min()
    h /= h.max() + 1e-12
    if furrow < 1.0:
        h = furrow * h + (1.0 - furrow) * np.clip(smooth, 0.0, 1.0)
    return h.astype(np.float32)


def bark_textures(tint, size: int = 256, seed: int = 0, depth: float = 0.03, furrow: float = 1.0):
    """(albedo uint8 H×W×3 sRGB, normal uint8 H×W×3) for bark that tiles in u and v.

    `tint` is the bark's mean linear RGB. V runs along the stem (mesh.py's bark UVs), so the
    fissures are vertical. `depth` is the furrow depth as a fraction of the tile width (the
    stem's circumference), so the normal map looks the same at any `size`. Normals come from
    periodic central differences, so the normal map tiles exactly as the height does.
    `furrow` (0..1) goes from smooth bark with lenticels to deeply furrowed plates.
    """
    t = _check_color("tint", tint).astype(np.float32)
    h = bark_height(size, seed, furrow)
    rb, rf = (np.random.default_rng(s) for s in np.random.SeedSequence([int(seed), 0xC0105]).spawn(2))
    blot = _torus_noise(rb, size, 6.0, 3.0, 1)[0]
    fib = _torus_noise(rf, size, 48.0, 6.0, 1)[0]
    # Furrows dark and warm, ridge tops lighter and greyer (weathered); fibres and slow
    # blotches so a plate is not one flat colour.
    grey = np.float32(t.mean())
    top = 0.6 * t + 0.4 * grey
    low = t * np.array([0.30, 0.25, 0.22], dtype=np.float32)
    k = _smoothstep(0.08, 0.6, h)[..., None]
    lin = low + (top * 1.3 - low) * k
    lin *= (1.0 + 0.08 * blot + 0.07 * fib)[..., None] * (0.85 + 0.3 * h)[..., None]
    lin *= t / np.maximum(lin.reshape(-1, 3).mean(axis=0), 1e-6)  # mean albedo = tint
    albedo = _to_srgb8(lin)
    s = depth * size
    dx = (np.roll(h, -1, axis=1) - np.roll(h, 1, axis=1)) * (0.5 * s)  # dh / d(column)
    dy = (np.roll(h, -1, axis=0) - np.roll(h, 1, axis=0)) * (0.5 * s)  # dh / d(row), row = −Y
    inv = 127.5 / np.sqrt(dx * dx + dy * dy + 1.0)
    normal = np.empty(h.shape + (3,), dtype=np.uint8)
    normal[..., 0] = np.round(127.5 - dx * inv)
    normal[..., 1] = np.round(127.5 + dy * inv)
    normal[..., 2] = np.round(127.5 + inv)
    return albedo, normal


# ---------------------------------------------------------------------------------- PNG


def png_bytes(array: np.ndarray) -> bytes:
    """PNG of a uint8 H×W×3 (RGB) or H×W×4 (RGBA) array; no metadata, so bytes are repeatable."""
    from PIL import Image

    a = np.ascontiguousarray(array)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] not in (3, 4):
        raise ValueError(f"png_bytes wants uint8 H×W×3 or H×W×4, got {a.dtype} {a.shape}")
    img = Image.fromarray(a)
    buf = io.BytesIO()
    img.save(buf, format="PNG", compress_level=PNG_COMPRESS_LEVEL, compress_type=PNG_STRATEGY)
    return buf.getvalue()


def png_bytes_unfiltered(array: np.ndarray) -> bytes:
    """PNG of a uint8 H×W×4 array with no row filter and zlib level 1: for the impostor's
    1024² atlases, 2–3× faster than png_bytes (its per-row adaptive filter), and, on cut-outs
    with a cleared background, smaller overall (normal + depth atlas −27 to −30 %, albedo
    +3 to +10 %, measured on four species)."""
    a = np.ascontiguousarray(array)
    if a.dtype != np.uint8 or a.ndim != 3 or a.shape[2] != 4:
        raise ValueError(f"png_bytes_unfiltered wants uint8 H×W×4, got {a.dtype} {a.shape}")
    h, w = a.shape[:2]
    raw = np.zeros((h, 1 + 4 * w), np.uint8)  # filter byte 0: None
    raw[:, 1:] = a.reshape(h, 4 * w)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return len(data).to_bytes(4, "big") + kind + data + zlib.crc32(kind + data).to_bytes(4, "big")

    header = w.to_bytes(4, "big") + h.to_bytes(4, "big") + bytes((8, 6, 0, 0, 0))  # RGBA8
    return (
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(raw.tobytes(), 1))
        + chunk(b"IEND", b"")
    )


# ---------------------------------------------------------------------------------- colours

# Linear RGB (glTF baseColorFactor space). Chosen by eye for each species' real foliage and
# bark; the by-shape and generic entries are the fallbacks.
DEFAULT_LEAF_COLOR: dict[str | int, tuple[float, float, float]] = {
    "default": (0.16, 0.30, 0.06),
    0: (0.16, 0.30, 0.06),  # broadleaf
    1: (0.07, 0.16, 0.05),  # needles
    2: (0.07, 0.17, 0.06),  # narrow needles / willow-like
    3: (0.14, 0.27, 0.06),
    4: (0.15, 0.28, 0.06),
    5: (0.12, 0.17, 0.06),  # seeds, knots, tiny blobs: olive
    6: (0.10, 0.22, 0.05),  # palm fronds
    7: (0.15, 0.29, 0.05),  # palmate
    "balsam_fir": (0.04, 0.11, 0.04),
    "black_tupelo": (0.10, 0.22, 0.04),
    "ca_black_oak": (0.12, 0.20, 0.05),
    "desert_bush": (0.16, 0.18, 0.08),
    "eastern_cottonwood": (0.15, 0.30, 0.06),
    "european_larch": (0.16, 0.34, 0.08),
    "fan_palm": (0.12, 0.24, 0.07),
    "lombardy_poplar": (0.13, 0.28, 0.05),
    "palm": (0.10, 0.22, 0.05),
    "quaking_aspen": (0.20, 0.36, 0.06),
    "rush": (0.20, 0.24, 0.08),
    "sassafras": (0.18, 0.34, 0.06),
    "shave_grass": (0.12, 0.25, 0.07),
    "tamarack": (0.14, 0.30, 0.08),
    "weeping_willow": (0.20, 0.33, 0.07),
}
DEFAULT_BARK_COLOR: dict[str, tuple[float, float, float]] = {
    "default": (0.13, 0.09, 0.06),
    "balsam_fir": (0.17, 0.15, 0.13),  # smooth grey-brown
    "black_tupelo": (0.11, 0.09, 0.08),  # dark, blocky
    "ca_black_oak": (0.08, 0.07, 0.06),  # nearly black furrows
    "desert_bush": (0.20, 0.15, 0.10),
    "eastern_cottonwood": (0.20, 0.19, 0.17),  # ash-grey, deeply furrowed
    "european_larch": (0.17, 0.08, 0.05),  # reddish brown
    "fan_palm": (0.22, 0.17, 0.11),
    "lombardy_poplar": (0.16, 0.15, 0.13),
    "palm": (0.22, 0.17, 0.11),
    "quaking_aspen": (0.45, 0.44, 0.37),  # pale, chalky
    "rush": (0.15, 0.22, 0.07),  # green stems
    "sassafras": (0.17, 0.10, 0.07),  # orange-brown
    "shave_grass": (0.12, 0.22, 0.08),  # green stems
    "tamarack": (0.16, 0.09, 0.07),
    "weeping_willow": (0.14, 0.11, 0.08),
}

# How furrowed each species' bark is (bark_textures' `furrow`): 1 deep plates, 0 smooth.
DEFAULT_BARK_FURROW: dict[str, float] = {
    "default": 1.0,
    "balsam_fir": 0.35,  # smooth with resin blisters until old
    "desert_bush": 0.6,
    "european_larch": 0.8,
    "fan_palm": 0.2,
    "lombardy_poplar": 0.8,
    "palm": 0.2,
    "quaking_aspen": 0.1,  # smooth, chalky, dark lenticels
    "rush": 0.0,  # green culms
    "sassafras": 0.9,
    "shave_grass": 0.0,
    "tamarack": 0.7,
    "weeping_willow": 0.9,
}


def _species_key(params) -> str:
    return str(getattr(params, "name", "")).lower().replace(" ", "_").replace("-", "_")


def species_colors(params) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(leaf, bark) linear RGB for a species: its own LeafColor/BarkColor fields if Params ever
    grows them, else the table by species name, else by leaf shape, else the generic default.
    """
    name = _species_key(params)
    leaf = getattr(params, "leaf_color", None)
    bark = getattr(params, "bark_color", None)
    if leaf is None:
        leaf = DEFAULT_LEAF_COLOR.get(name) or DEFAULT_LEAF_COLOR.get(
            int(getattr(params, "leaf_shape", 0)), DEFAULT_LEAF_COLOR["default"]
        )
    if bark is None:
        bark = DEFAULT_BARK_COLOR.get(name, DEFAULT_BARK_COLOR["default"])
    return tuple(float(c) for c in leaf), tuple(float(c) for c in bark)


@dataclass(frozen=True, eq=False)
class TreeTextures:
    """A species' leaf atlas and bark maps, ready to embed (see `pngs`)."""

    leaf: LeafAtlas
    bark_albedo: np.ndarray  # uint8 (N, N, 3) sRGB
    bark_normal: np.ndarray  # uint8 (N, N, 3) tangent space, OpenGL/glTF convention

    def pngs(self) -> dict[str, bytes]:
        """PNG bytes by role: "leaf" (RGBA), "bark" (RGB), "bark_normal" (RGB)."""
        return {
            "leaf": png_bytes(self.leaf.rgba),
            "bark": png_bytes(self.bark_albedo),
            "bark_normal": png_bytes(self.bark_normal),
        }


def species_textures(
    params, seed: int = 0, leaf_size: int = 512, bark_size: int = 256, variants: int = 4
) -> TreeTextures:
    """Everything a writer needs for one species: its colours, its LeafShape outline, its
    leaf width / length (LeafScaleX) so veins keep their angles on the stretched card, and
    how furrowed its bark is."""
    leaf_rgb, bark_rgb = species_colors(params)
    aspect = float(getattr(params, "leaf_scale_x", 0.5))
    atlas = leaf_atlas(
        int(getattr(params, "leaf_shape", 0)), leaf_rgb, leaf_size, variants, seed, aspect=aspect
    )
    furrow = DEFAULT_BARK_FURROW.get(_species_key(params), DEFAULT_BARK_FURROW["default"])
    albedo, normal = bark_textures(bark_rgb, bark_size, seed, furrow=furrow)
    return TreeTextures(atlas, albedo, normal)
