"""LOD pops, measured: two LODs rendered at the size the tree has on screen when one hands over
to the other, compared as alpha-tested coverage masks.

    pops = lod_pops(asset, lod_options)     # one Pop per switch k → k+1
    # Result: Pop(switch=1, distance=10.0, pixels=..., iou=0.93, coverage=1.01) ...

The masks come from the project's renderer (render.Renderer): its depth pass, which skins on the
GPU and discards cut-out texels exactly as its colour pass (hashed alpha once a texel spans many
pixels), drawn at SUPERSAMPLE× and box-filtered, so a pixel's value is the fraction of it the
tree covers (its expected coverage, not one sample's luck). The camera is far away with a narrow field of view so that one pixel spans what a
pixel of the real `--fov`/`--width` view spans at the switch distance: leaves are as big (in
pixels) as a user sees them when the LOD changes, and the whole tree is in the picture.

What is compared, per view (the rest pose, side views around the tree):
  * coverage: Σ mask of LOD k+1 / Σ mask of LOD k — the crown's covered area (1 = no change);
  * silhouette IoU: Σ min / Σ max of the two masks after a box blur of BLUR_PX pixels. The blur
    is the eye's: two different but equally dense leaf scatters read as the same crown, while a
    crown whose leaves clump into fronds, grow or thin out does not. Without it, two random
    scatters of the same density would score p/(2 − p) (0.43 at 60 % cover) however alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

BLUR_PX = 3  # silhouette scale: a box of this many pixels (odd)
# Sub-samples per pixel side. Leaves a fraction of a pixel across are point-sampled, so with
# few samples the mask is noise: LOD0 against itself moved a tenth of a pixel scored IoU 0.74
# (larch), 0.85 (palm) at 2 × 2 (bench/lod_cards_bench.py --floor), 0.95-0.98 at 8 × 8. At
# 6 × 6 the larch's switches read 0.89-0.92 where 2 × 2 read 0.78-0.83: the pop measured, not
# the sampling.
SUPERSAMPLE = 6
MAX_PX = 768  # longest image side; bigger switch sizes are drawn at this size
VIEWS = (-90.0, 0.0)  # camera azimuths (degrees, the preview's convention)
ELEVATION = 5.0  # camera height angle, degrees


@dataclass(frozen=True)
class Pop:
    """What changes on screen at one LOD switch (LOD `switch` − 1 → `switch`), worst view."""

    switch: int  # index of the LOD that takes over
    distance: float  # metres at which it does
    pixels: int  # tree's longest side on screen at the switch, as rendered
    iou: float  # silhouette IoU, the lowest over the views
    coverage: float  # covered area ratio new / old, the farthest from 1 over the views


def metres_per_pixel(distance: float, options) -> float:
    """What one pixel of the `options` view (horizontal fov, width in pixels) spans at `distance`."""
    return 2.0 * distance * math.tan(0.5 * math.radians(options.fov_deg)) / options.width


def _camera(points: np.ndarray, azimuth: float, size_px: tuple[int, int], m_per_px: float):
    """A far camera looking at the points' bounding box whose pixels span `m_per_px` there."""
    from .render_view import Camera, direction

    lo, hi = points.min(0), points.max(0)
    target = 0.5 * (lo + hi)
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    dist = 50.0 * radius
    half_h = 0.5 * size_px[1] * m_per_px
    fov = 2.0 * math.degrees(math.atan(half_h / dist))
    eye = target + direction(azimuth, ELEVATION) * dist
    return Camera(eye=eye, target=target, near=dist - 2 * radius, far=dist + 2 * radius, fov_deg=fov)


def _extent(points: np.ndarray, azimuth: float) -> tuple[float, float]:
    """(width, height) in metres of the points seen from `azimuth` (orthographic)."""
    from .render_view import direction, look_at

    view = look_at(np.zeros(3), -direction(azimuth, ELEVATION))
    v = points @ view[:3, :3].T
    return float(np.ptp(v[:, 0])), float(np.ptp(v[:, 1]))


def coverage_masks(
    drawables, m_per_px: float, views=VIEWS, max_px: int = MAX_PX, margin_px: int = 4
) -> tuple[list[list[np.ndarray]], int]:
    """Per drawable, per view: a float32 (H, W) mask, each pixel's covered fraction, all with
    the same camera (fitted to the first drawable) at `m_per_px` metres per pixel (coarser when
    the tree would exceed `max_px`). Returns (masks, longest side of the tree in pixels)."""
    from .render import Renderer

    pts = np.concatenate([p.positions for p in drawables[0].parts if len(p.positions)]).astype(np.float64)
    out: list[list[np.ndarray]] = [[] for _ in drawables]
    longest = 0
    for az in views:
        w_m, h_m = _extent(pts, az)
        scale = max(1.0, max(w_m, h_m) / m_per_px / (max_px - 2 * margin_px))
        mpp = m_per_px * scale
        size = (int(math.ceil(w_m / mpp)) + 2 * margin_px, int(math.ceil(h_m / mpp)) + 2 * margin_px)
        longest = max(longest, int(round(max(w_m, h_m) / mpp)))
        cam = _camera(pts, az, size, mpp)
        for i, d in enumerate(drawables):
            with Renderer(d, max(size[0], 8), max(size[1], 8), SUPERSAMPLE) as r:
                out[i].append(_mask(r, cam))
    return out, longest


def _mask(r, camera) -> np.ndarray:
    """Covered fraction per pixel: the renderer's alpha-tested depth pass, box-filtered."""
    ctx = r.ctx
    W, H = r.width * r.ss, r.height * r.ss
    depth = ctx.depth_renderbuffer((W, H))
    fbo = ctx.framebuffer(depth_attachment=depth)
    fbo.use()
    ctx.viewport = (0, 0, W, H)
    fbo.clear(depth=1.0)
    ctx.enable(ctx.DEPTH_TEST)
    ctx.disable(ctx.CULL_FACE)
    skin = np.broadcast_to(np.eye(4), (max(r.scene.n_joints, 1), 4, 4))
    r.skin_tex.write(np.ascontiguousarray(np.transpose(skin, (0, 2, 1)), "f4").tobytes())
    r.skin_tex.use(location=0)
    from .render import HASH_LOD, MIP_BIAS

    prog = r.depth_prog
    r._set(prog, "view_proj", camera.view_proj(r.width / r.height))
    r._set(prog, "skin", 0)
    r._set(prog, "base_tex", 2)
    r._set(prog, "mip_bias", MIP_BIAS)
    r._set(prog, "hash_from", HASH_LOD)
    for g in r.parts:
        r._material(prog, g)
        g.depth_vao.render()
    z = np.frombuffer(fbo.read(components=1, attachment=-1, dtype="f4"), dtype=np.float32).reshape(H, W)[::-1]
    fbo.release()
    depth.release()
    cover = (z < 1.0).astype(np.float32)
    return cover.reshape(r.height, r.ss, r.width, r.ss).mean(axis=(1, 3))


def _blur(m: np.ndarray, k: int = BLUR_PX) -> np.ndarray:
    """Box blur (k × k, edges padded with zeros) by cumulative sums."""
    if k <= 1:
        return m
    p = k // 2
    a = np.pad(m.astype(np.float64), ((p + 1, p), (p + 1, p)))
    c = a.cumsum(0).cumsum(1)
    s = c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]
    return s / (k * k)


def compare(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """(silhouette IoU, coverage ratio b / a) of two coverage masks of one view."""
    ba, bb = _blur(a), _blur(b)
    union = float(np.maximum(ba, bb).sum())
    iou = float(np.minimum(ba, bb).sum()) / union if union > 0 else 1.0
    ca = float(a.sum())
    return iou, (float(b.sum()) / ca if ca > 0 else 1.0)


def lod_pops(asset, options, views=VIEWS, max_px: int = MAX_PX) -> list[Pop]:
    """One Pop per LOD switch of `asset` (LOD k → k+1 at LOD k+1's distance), rest pose."""
    from .drawable import from_asset

    pops = []
    for k in range(1, len(asset.lods)):
        d = asset.lods[k].distance
        pair = [from_asset(asset, k - 1), from_asset(asset, k)]
        masks, px = coverage_masks(pair, metres_per_pixel(d, options), views, max_px)
        scores = [compare(a, b) for a, b in zip(*masks)]
        pops.append(
            Pop(
                switch=k,
                distance=float(d),
                pixels=px,
                iou=min(s[0] for s in scores),
                coverage=max((s[1] for s in scores), key=lambda c: abs(c - 1.0)),
            )
        )
    return pops
