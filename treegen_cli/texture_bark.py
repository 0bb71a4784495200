"""Bark maps: a tileable height field of long plates split by furrows, and from it the albedo
and tangent-space normal map (periodic in u and v, so they tile around and along every stem)."""

from __future__ import annotations

import math

import numpy as np

from .texture_color import check_color, smoothstep, to_srgb8


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
    cross = (1.0 - smoothstep(0.0, 0.10, np.abs(c[0]))) * smoothstep(0.8, 1.6, c[1])
    lenticel = (1.0 - smoothstep(0.0, 0.22, np.abs(c[0]))) * smoothstep(0.4, 1.4, c[1])
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
    wall = smoothstep(0.0, 1.0, border / width)
    crown = smoothstep(0.0, 1.0, border / (5.0 * width))
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
    t = check_color("tint", tint).astype(np.float32)
    h = bark_height(size, seed, furrow)
    rb, rf = (np.random.default_rng(s) for s in np.random.SeedSequence([int(seed), 0xC0105]).spawn(2))
    blot = _torus_noise(rb, size, 6.0, 3.0, 1)[0]
    fib = _torus_noise(rf, size, 48.0, 6.0, 1)[0]
    # Furrows dark and warm, ridge tops lighter and greyer (weathered); fibres and slow
    # blotches so a plate is not one flat colour.
    grey = np.float32(t.mean())
    top = 0.6 * t + 0.4 * grey
    low = t * np.array([0.30, 0.25, 0.22], dtype=np.float32)
    k = smoothstep(0.08, 0.6, h)[..., None]
    lin = low + (top * 1.3 - low) * k
    lin *= (1.0 + 0.08 * blot + 0.07 * fib)[..., None] * (0.85 + 0.3 * h)[..., None]
    lin *= t / np.maximum(lin.reshape(-1, 3).mean(axis=0), 1e-6)  # mean albedo = tint
    albedo = to_srgb8(lin)
    s = depth * size
    dx = (np.roll(h, -1, axis=1) - np.roll(h, 1, axis=1)) * (0.5 * s)  # dh / d(column)
    dy = (np.roll(h, -1, axis=0) - np.roll(h, 1, axis=0)) * (0.5 * s)  # dh / d(row), row = −Y
    inv = 127.5 / np.sqrt(dx * dx + dy * dy + 1.0)
    normal = np.empty(h.shape + (3,), dtype=np.uint8)
    normal[..., 0] = np.round(127.5 - dx * inv)
    normal[..., 1] = np.round(127.5 + dy * inv)
    normal[..., 2] = np.round(127.5 + inv)
    return albedo, normal
