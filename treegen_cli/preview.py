"""`treegen preview`: a picture (or a looping GIF) of a tree, rendered headless.

Input is a species file (grown in-process), or a file `treegen make` wrote (.glb/.gltf read back
with our own glTF reader, .usda/.usdc/.usdz through pxr's UsdSkel). Each becomes a render.Drawable:
parts in Y-up world space plus `skinning(t)`, the per-joint matrices S_j(t) = W_j(t)·B_j⁻¹ that
an engine would upload — joint world matrices posed from the clip, times inverse bind. The
renderer applies them per vertex, so what you see is what the file's skin and animation do.
"""

from __future__ import annotations

import json
import math

import os
import re
from contextlib import nullcontext
from dataclasses import dataclass, replace
from pathlib import Path

import click
import numpy as np

from . import exchange
from .clip import loop_times
from .drawable import Drawable, Part, from_asset
from .bundled import LIST_HINT, bundled_species, not_found
from .errors import TreegenError
from .params import load_params
from .options import resolve
from .pipeline import build_asset
from .render_view import frame_points, skin_points


@dataclass(frozen=True)
class PreviewOptions:
    """Camera and output; angles in degrees, size in pixels."""

    azimuth: float = -90.0  # camera bearing, counter-clockwise from +X (Z up): −90 looks
    # along +Y, so the default wind (towards +X) blows left → right
    elevation: float = 8.0  # camera height angle above the horizon
    width: int = 512
    height: int = 512
    lod: int = 0
    seed: int | None = None  # species input only (None: 0, and a written tree is fine)
    fps: float = 15.0  # GIF frames per second of the wind loop
    sun_azimuth: float | None = None  # None: 50° left of the camera
    sun_elevation: float = 50.0


DEFAULTS = PreviewOptions()


# ------------------------------------------------------------------------------ front door


def load_scene(path: str | os.PathLike, options: PreviewOptions = DEFAULTS) -> Drawable:
    """A species file or bundled species name (grown here) or a written tree (read back by
    exchange) as a Drawable."""
    path = exchange.check_input(resolve_input(path))
    if not exchange.is_species(path):
        if options.seed is not None:  # even 0: the tree was grown with its own seed
            raise TreegenError(f"--seed {options.seed}: {path} is a written tree, grown with its own seed")
        return exchange.read_drawable(path, options.lod, refuse_forest=True)
    params = load_params(path)
    # LOD 0 alone needs no LOD chain: skip building (and cutting leaves for) the others; the
    # others as `make` builds them, the impostor last
    job = resolve({"seed": options.seed or 0})
    make = replace(job.options, lod=None, impostor=None) if options.lod == 0 else job.options
    try:
        asset, _ = build_asset(params, job.seed, make)
    except TreegenError as e:
        raise TreegenError(f"{path}: {e}") from None
    return from_asset(asset, options.lod, label=str(path))


def resolve_input(value: str | os.PathLike) -> Path:
    """INPUT as a file: an existing path wins, then a bundled species name (bundled.py)."""
    text = os.fspath(value)
    path = Path(text)
    if path.is_dir():
        raise TreegenError(
            f"{text} is a directory; expected a tree file (.glb .gltf .usd*), "
            f"a species file (.txt .xml) or a bundled species name ({LIST_HINT})"
        )
    if path.is_file():
        return path
    hit = bundled_species(text)
    if hit is not None:
        return hit
    if path.suffix.lower() in exchange.SPECIES or not path.suffix:
        raise not_found(f"species '{text}'", text)
    return path  # exchange.check_input names what is missing


def framing_points(scene: Drawable, times: np.ndarray, max_points: int = 20000) -> np.ndarray:
    """Up to `max_points` vertices (evenly strided), impostor cards by their opaque texels,
    skinned at each of `times`: the bounds the camera must fit over the whole loop."""
    out = []
    total = sum(len(p.positions) for p in scene.parts)
    step = max(1, total // max_points)
    poses = scene.pose(times)
    for p in scene.parts:
        shown = opaque_points(p) if p.impostor else None
        if shown is None:
            sel = slice(0, len(p.positions), step)
            shown = p.positions[sel], np.asarray(p.joints)[sel], p.weights[sel]
        for pose in poses:  # a dozen poses at most
            out.append(skin_points(*shown, pose))
    return np.concatenate(out) if out else np.zeros((1, 3))


def opaque_points(part: Part, budget: int = 50_000):
    """(points, joints, weights) on `part`'s triangles where its texture is opaque, or None
    (no cut-out texture, or nothing shown). The impostor's cards are squares around the tree's
    bounding sphere: framed by their corners, the aspen came out 21 % shorter than at its last
    geometric LOD, and by the box in the file's impostor metadata its camera still stood 13 %
    (60° up: 48 %) farther off, as near corners loom in perspective. What the cards show frames
    within 2–5 % of that LOD's camera at the default view. Sampled on a barycentric lattice
    about a texel apart (at most `budget` samples); a sample rides its nearest corner's joints
    (cards are rigid)."""
    if not part.textured or part.alpha_cutoff is None or not len(part.indices):
        return None
    tri = np.asarray(part.indices, np.int64).reshape(-1, 3)
    h, w = part.texture.shape[:2]
    uv = part.uvs[tri].astype(np.float64)  # (T, 3, 2)
    texels = float((np.abs(uv - np.roll(uv, 1, axis=1)) * (w, h)).max())
    n = int(max(1, min(np.ceil(texels), np.sqrt(2 * budget / len(tri)))))
    a, b = np.indices((n + 1, n + 1)).reshape(2, -1)
    keep = a + b <= n
    bary = np.stack([n - a[keep] - b[keep], a[keep], b[keep]], 1) / n  # (S, 3)
    st = np.einsum("sk,tkd->tsd", bary, uv)
    for axis, mode in enumerate(part.wrap):  # MIRROR read as REPEAT: close enough to frame
        st[..., axis] = np.clip(st[..., axis], 0, 1) if mode == "CLAMP" else np.mod(st[..., axis], 1)
    col = np.minimum((st[..., 0] * w).astype(np.int64), w - 1)
    row = np.minimum(((1 - st[..., 1]) * h).astype(np.int64), h - 1)  # texture: top row first
    opaque = part.texture[row, col, 3] / 255.0 * part.opacity >= part.alpha_cutoff
    if not opaque.any():
        return None
    corner = tri[:, bary.argmax(1)][opaque]  # (K,) vertex of each kept sample
    pts = np.einsum("sk,tkd->tsd", bary, part.positions[tri].astype(np.float64))[opaque]
    return pts, np.asarray(part.joints)[corner], part.weights[corner]


def camera_for(scene: Drawable, options: PreviewOptions, times: np.ndarray):
    """One camera that fits the tree, in the image's width and height, at every one of `times`
    (up to 12 sampled)."""
    sample = times if len(times) <= 12 else times[np.linspace(0, len(times) - 1, 12).astype(int)]
    return frame_points(
        framing_points(scene, sample),
        options.azimuth,
        options.elevation,
        aspect=options.width / options.height,
    )


def sun_angles(options: PreviewOptions) -> tuple[float, float]:
    az = options.azimuth - 50.0 if options.sun_azimuth is None else options.sun_azimuth
    return az, options.sun_elevation


def _renderer(scene: Drawable, options: PreviewOptions, renderer=None):
    """`renderer` as a no-op context, or a new Renderer for `scene` (an EGL context)."""
    from .render import Renderer  # lazy: moderngl/EGL only when something is drawn

    return nullcontext(renderer) if renderer is not None else Renderer(scene, options.width, options.height)


def render_still(
    scene: Drawable, options: PreviewOptions = DEFAULTS, renderer=None, camera=None
) -> np.ndarray:
    """The rest (bind) pose, no wind, as uint8 (height, width, 3); `renderer`: an open one to
    reuse; `camera`: a fixed one (a layout's), else one framing the scene. (The wind clip's
    t = 0 is a swayed pose, not the rest pose the help promises.)"""
    rest = replace(scene, skinning=None)
    times = np.zeros(1)
    camera = camera or camera_for(rest, options, times)
    with _renderer(scene, options, renderer) as r:
        az, el = sun_angles(options)
        return r.render(camera, rest.pose(times)[0], az, el)


def render_loop(scene: Drawable, options: PreviewOptions = DEFAULTS, renderer=None) -> list[np.ndarray]:
    """Frames over the whole wind loop at t = 0, 1/fps, … up to but not including t = duration:
    the clip's closing key repeats its first pose, and a GIF wraps back to frame 0, so drawing
    it too would hold that pose twice at the seam. One fixed camera fits every frame."""
    if scene.duration <= 0 or scene.skinning is None:
        raise TreegenError(f"{scene.label}: has no wind animation to render (made with --no-wind?)")
    times = loop_times(scene.duration, options.fps)[:-1]
    camera = camera_for(scene, options, times)
    frames = []
    with _renderer(scene, options, renderer) as r:
        az, el = sun_angles(options)
        for pose in scene.pose(times):  # frames: tens
            frames.append(r.render(camera, pose, az, el))
    return frames


# ------------------------------------------------------------------------------ command


def _layout_only(animate, lod: int, seed: int | None) -> None:
    """What a layout's preview does not take: it draws a still, each tree at the LOD its
    camera needs, with the layout's seeds."""
    for given, flag in (
        (animate is not None, "--animate"),
        (lod != 0, "--lod"),
        (seed is not None, "--seed"),
    ):
        if given:
            raise TreegenError(
                f"{flag}: not for a forest layout (its preview is a still, each tree at the LOD "
                "its camera needs, with the layout's seeds); leave it out"
            )


def _size(text: str) -> tuple[int, int]:
    m = re.fullmatch(r"\s*(\d+)\s*(?:[xX×]\s*(\d+))?\s*", text or "")
    if not m:
        raise TreegenError(f"--size '{text}': expected pixels as N or WxH, e.g. 512 or 800x600")
    w = int(m.group(1))
    h = int(m.group(2)) if m.group(2) else w
    if not (8 <= w <= 8192 and 8 <= h <= 8192):
        raise TreegenError(f"--size '{text}': each side must be in 8..8192 pixels")
    return w, h


@click.command("preview")
@click.argument("input_path", metavar="INPUT")
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    help="Still image of the rest pose: .png (optimised) or .jpg.",
)
@click.option(
    "--animate",
    type=click.Path(path_type=Path),
    help="Animated GIF of the whole wind loop, seamless (the closing pose is not drawn twice) "
    "and as long as the clip, skinned on the GPU from the file's joints and keys, like an engine.",
)
@click.option(
    "--azimuth",
    type=float,
    default=DEFAULTS.azimuth,
    show_default=True,
    help="Camera bearing, degrees counter-clockwise from +X seen from above "
    "(Z-up tree space); -90 looks along +Y, so the default wind blows left → right. "
    "Refused for a layout with a camera, which is seen from that camera.",
)
@click.option(
    "--elevation",
    type=float,
    default=DEFAULTS.elevation,
    show_default=True,
    help="Camera height angle above the horizon, degrees (-89..89).",
)
@click.option(
    "--sun",
    "sun",
    type=float,
    default=None,
    metavar="DEGREES",
    help="Sun bearing, degrees as --azimuth (the way the light comes from) [default: 50° "
    "left of the camera, so it turns with it]; fixed, it shows how a LOD or the impostor "
    "is lit from each side.",
)
@click.option(
    "--size",
    "size",
    default=str(DEFAULTS.width),
    show_default=True,
    metavar="N|WxH",
    help="Image size in pixels (square N, or width x height).",
)
@click.option("--lod", type=int, default=0, show_default=True, help="Which LOD to render (0 = full detail).")
@click.option("--seed", type=int, help="Seed when INPUT is a species file (default 0).")
@click.option(
    "--fps",
    type=float,
    default=DEFAULTS.fps,
    show_default=True,
    help="GIF frames per second of the wind loop (frames = duration × fps).",
)
@click.option(
    "--png-colors",
    type=click.IntRange(0, 256),
    default=0,
    show_default=True,
    help="Quantise the PNG to this many palette colours (smaller files, e.g. 256 "
    "for a README); 0 keeps full colour.",
)
@click.option("--json", "as_json", is_flag=True, help="Print what was written as JSON.")
def preview_command(
    input_path, output, animate, azimuth, elevation, sun, size, lod, seed, fps, png_colors, as_json
):
    """Render INPUT headless (OpenGL on EGL; no display needed): a species file (.txt .xml,
    grown in-process) or bundled species name (`treegen species`), a tree written by
    `treegen make` (.glb .gltf .usda .usdc .usdz), or a forest layout (.json, as `treegen
    forest` takes; a still from its camera, each tree at the LOD that camera needs).
    Lit by a sun with shadows and sky light; bark and leaves as their materials say: colours,
    textures (cut-out leaves, casting cut-out shadows; bark with its normal map), framed
    automatically from the bounds of the whole animation."""
    import time

    if output is None and animate is None:
        raise TreegenError("preview: give an image with -o out.png and/or --animate out.gif")
    if output is not None:  # fail before anything is grown or rendered
        exchange.check_suffix(output, exchange.STILLS, "image", "-o")
    if animate is not None:
        exchange.check_suffix(animate, exchange.LOOPS, "animation", "--animate")
    if not -89.0 <= elevation <= 89.0:
        raise TreegenError(f"--elevation {elevation:g}: allowed range -89..89 degrees")
    if not 0.5 <= fps <= 60.0:
        raise TreegenError(f"--fps {fps:g}: allowed range 0.5..60 frames per second")
    if lod < 0:
        raise TreegenError(f"--lod {lod}: must be 0 or more")
    if seed is not None:
        resolve({"seed": seed})  # its range, as make's (a negative seed crashed the generator)
    width, height = _size(size)
    if sun is not None and not math.isfinite(sun):
        raise TreegenError(f"--sun {sun:g}: give a bearing in degrees, e.g. -140")
    options = PreviewOptions(
        azimuth=azimuth,
        elevation=elevation,
        sun_azimuth=sun,
        width=width,
        height=height,
        lod=lod,
        seed=seed,
        fps=fps,
    )
    t0 = time.perf_counter()
    camera, forest = None, None
    if Path(input_path).suffix.lower() == ".json":  # a forest layout: seen from its camera
        from .preview_forest import bearing, forest_view

        from .commands.flags import given

        _layout_only(animate, lod, seed)
        framing = [f"--{k}" for k in given(dict(azimuth=azimuth, elevation=elevation))]
        scene, camera, forest = forest_view(input_path, azimuth, elevation, width / height, framing=framing)
        options = replace(options, azimuth=bearing(camera))  # the default sun turns with it
    else:
        scene = load_scene(input_path, options)
    lines, summary = [], {"input": str(input_path), "width": width, "height": height, "lod": lod}
    if forest is not None:
        summary = {"input": str(input_path), "width": width, "height": height, **forest}
    with _renderer(scene, options) as renderer:  # one GL context for the still and the loop
        if output is not None:
            exchange.save_still(render_still(scene, options, renderer, camera), output, png_colors)
            what = (
                f"LOD {lod}"
                if forest is None
                else f"{forest['trees']:,} trees from the {forest['camera']} camera, per LOD "
                + " ".join(f"{n:,}" for n in forest["trees_per_lod"])
            )
            lines.append(f"wrote {output}  ({width}×{height}, {what})")
            summary["image"] = str(output)
        if animate is not None:
            frames = render_loop(scene, options, renderer)
            exchange.save_loop(frames, animate, scene.duration)
            lines.append(
                f"wrote {animate}  ({width}×{height}, {len(frames)} frames over "
                f"{scene.duration:.2f} s, LOD {lod})"
            )
            summary |= {
                "animation": str(animate),
                "frames": len(frames),
                "duration_s": round(float(scene.duration), 4),
            }
    summary["seconds"] = round(time.perf_counter() - t0, 3)
    if as_json:
        click.echo(json.dumps(summary, indent=2))
        return
    for line in lines:
        click.echo(line)
    click.echo(f"  {summary['seconds']:.2f} s")
