"""The impostor's colour against the coarsest geometric LOD: mean linear RGB of the crown's
pixels, both rendered by the preview renderer at one fixed camera.

    python bench/impostor_colour_bench.py [--species quaking_aspen,...] [--size 192]

Each species is built as `treegen make` builds it (default options, no wind). One camera per
view (azimuths −90° and −45°: a card face-on and the crossed cards at an angle, 8° up, framed
on the coarsest LOD) renders both LODs with the preview's sun (50° left of the camera); crown
pixels are those both LODs cover (differ from the background), so edges and framing cannot
bias the mean. Ratio: impostor / coarsest LOD, per channel, over the views' pixels.

Measured 2026-11-26 (impostor / LOD3, R G B), before (LEAF_SHADE 0.4 grey, the preview's crown
occlusion also on the cards) → after (LEAF_SHADE 0.37/0.40/0.50, no crown occlusion on cards):
    quaking_aspen   1.130 1.042 0.888  →  1.102 1.104 1.089
    balsam_fir      1.059 1.037 0.883  →  1.038 1.094 1.121
    ca_black_oak    0.817 0.804 0.643  →  0.808 0.852 0.779
    weeping_willow  1.026 0.910 0.798  →  0.999 0.954 0.985
Hue (blue/green) 0.85/0.85/0.80/0.88 → 0.99/1.02/0.91/1.03. With triangle cards in the
coarse LODs (lod_budget.py) the aspen's LOD3 read bluer (0.96; the test's 130 m LOD2 0.92),
LEAF_SHADE blue 0.50 → 0.515: 0.98/1.05/0.93/1.03. Then, on review, measured at the size the
impostor takes over (`--size 96`: the tree 96 px tall, ImpostorOptions.switch_px) rather than
192 px: the coarse LOD reads bluer there (sky between sub-pixel blades), 0.92/0.99/0.87/0.98
with blue 0.515; with 0.56 (and the preview's hash and tint per triangle card, not per pair):
    --size 96:  aspen 1.183 1.182 1.148  fir 1.036 1.115 1.170  oak 0.845 0.904 0.824
                willow 1.050 0.999 1.031    hue 0.97/1.05/0.91/1.03
    --size 192: hue 1.01/1.12/0.96/1.08 (the fir's cards bluer than its LOD3 when both are
                drawn twice the size they are used at). Brightness differs per species
(green 0.85-1.10×) and no constant removes it: the bark inside the crown (CROWN_SHADE 0.4 → 1.0
moves the oak to 0.97× but the aspen to 1.15×).
Contrast (last column): the std of the crown pixels' linear luminance, impostor / LOD3.
2026-11-27, the cards lit through a normal map of their own cells (impostor.card_textures)
instead of one bent normal per corner, `--size 96`, before → after (R G B ratio, contrast):
    quaking_aspen   1.175 1.175 1.134 0.49  →  1.257 1.261 1.266 0.76
    balsam_fir      1.034 1.114 1.166 0.60  →  0.896 0.992 1.072 0.81
    ca_black_oak    0.850 0.905 0.825 0.64  →  0.876 0.950 0.868 0.73
    weeping_willow  1.067 1.015 1.037 0.63  →  0.980 0.971 1.003 1.00
Relative to brightness (contrast / green ratio) 0.42/0.54/0.71/0.62 → 0.60/0.82/0.77/1.03;
hue (blue/green) 1.00/1.08/0.91/1.03. The leaves' own normals alone (no blur, no rounded
mass) gave 0.68-0.92 but lit leaves turned from the sun as black blotches a texel or two
wide. With their part along the view kept (the atlas flips double-sided leaves to face its
camera), each card faced its own view: at 45° between the cards the one turned to the sun
lit its half of the crown, the other went dark (0.67×, the geometric LOD 1.15× the other
way). LEAF_SHADE 0.37/0.40/0.56 → 0.445/0.483/0.706.

Dark share (last column): the impostor's crown pixels darker than all but 2 % of LOD3's (2 %
when it is as dark). 2026-11-27, a trial saw black blotches on the cards at the switch size:
each texel's normal was the sum of its 3 × 3 covered neighbours' (up to nine times the rounded
mass's weight), so clumps of leaves facing one way turned whole patches from the sun. Now their
mean plus 0.45 of the mass, LEAF_SHADE × 0.835 (0.372/0.403/0.589) for the brightness the dark
patches had pulled down; `--size 96`, before → after (R G B ratio, contrast, dark %):
    quaking_aspen   1.257 1.261 1.266 0.76  6.5  →  1.206 1.206 1.203 0.54 1.0
    balsam_fir      0.896 0.992 1.072 0.81 22.9  →  0.990 1.078 1.161 0.62 3.6
    ca_black_oak    0.876 0.950 0.868 0.73  5.6  →  0.859 0.917 0.852 0.64 0.7
    weeping_willow  0.980 0.971 1.003 1.00 18.7  →  1.041 0.996 1.040 0.68 3.2
The std measure of contrast was mostly the blotches: the card's own flat normal everywhere reads
0.47 (aspen), the mean with mass weights 0.3 / 0.35 / 0.45: contrast 0.59 / 0.57 / 0.54, dark
2.3 / 1.7 / 1.0 % (aspen), 9.2 / 6.5 / 3.6 % (fir); each texel's own normal (no mean) with
0.6: contrast 0.66, dark 5.1 % / 8.1 %, black specks instead of blotches. Looked at (128 px
previews of LOD3 and the impostor, aspen, fir, willow): the mean with 0.45 is the one without
black patches.

2026-11-28, `--size 96`: a card texel's normal the mean over all its 5 × 5 neighbours (an empty
one leaning nowhere), where it was over the covered ones only, so texels out at the fringe are
lit as the crown's rounded surface (impostor.card_textures), before → after (RGB ratio,
contrast, dark %):
    quaking_aspen   1.227 1.222 1.243 0.55 0.7  →  1.249 1.243 1.261 0.53 0.2
    balsam_fir      1.016 1.085 1.172 0.66 5.0  →  1.033 1.105 1.191 0.66 3.9
    ca_black_oak    0.891 0.938 0.893 0.66 0.2  →  0.909 0.958 0.909 0.67 0.0
    weeping_willow  1.077 1.017 1.096 0.70 2.2  →  1.103 1.041 1.118 0.69 1.0
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from treegen_cli import api
from treegen_cli.drawable import from_asset
from treegen_cli.params import load_params
from treegen_cli.pipeline import Timings, build_asset
from treegen_cli.render import Renderer
from treegen_cli.render_view import frame_points

ROOT = Path(__file__).resolve().parent.parent
VIEWS = (-90.0, -45.0)
DARK_PERCENTILE = 2.0


def linear(img: np.ndarray) -> np.ndarray:
    """sRGB uint8 → linear float."""
    c = img.astype(np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def crown_means(
    asset, size: int = 192, views=VIEWS, pair: tuple[int, int] | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(coarsest LOD, impostor) mean linear RGB over the pixels both cover, all views, their
    contrast: the standard deviation of linear luminance over those pixels (2,), and the
    impostor's dark share: its pixels darker than all but DARK_PERCENTILE % of the LOD's
    (blotches; DARK_PERCENTILE / 100 when it is as dark as the LOD). `pair`: two other LODs
    (indices), the first in the coarsest LOD's place."""
    k = len(asset.lods) - 1
    a, b = pair or (k - 1, k)
    scenes = [from_asset(asset, a), from_asset(asset, b)]
    pts = np.concatenate([p.positions for p in scenes[0].parts])
    pixels: list[list[np.ndarray]] = [[], []]
    for az in views:
        cam = frame_points(pts, az, 8.0)
        imgs, masks = [], []
        for scene in scenes:
            with Renderer(scene, size, size) as r:
                img = r.render(cam, sun_azimuth_deg=az - 50.0)
                bg = r.render(cam, sun_azimuth_deg=az - 50.0, draw_tree=False)
            imgs.append(linear(img))
            masks.append(np.abs(img.astype(int) - bg.astype(int)).sum(-1) > 30)
        both = masks[0] & masks[1]
        for i in range(2):
            pixels[i].append(imgs[i][both])
    geo, imp = (np.concatenate(p) if p else np.zeros((1, 3)) for p in pixels)
    lum = np.array([0.2126, 0.7152, 0.0722])
    dark = float(np.mean(imp @ lum < np.percentile(geo @ lum, DARK_PERCENTILE)))
    return geo.mean(0), imp.mean(0), np.array([np.std(geo @ lum), np.std(imp @ lum)]), dark


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default="quaking_aspen,balsam_fir,ca_black_oak,weeping_willow")
    ap.add_argument("--size", type=int, default=192)
    args = ap.parse_args()
    job = api.resolve({"no_wind": True})
    print(
        f"{'species':<20}{'LOD3 linear RGB':<24}{'impostor linear RGB':<24}{'impostor / LOD3 RGB':<20}"
        "contrast  dark %"
    )
    for name in args.species.split(","):
        asset, _ = build_asset(
            load_params(ROOT / "treegen_cli" / "species" / f"{name}.txt"), 0, job.options, Timings()
        )
        geo, imp, spread, dark = crown_means(asset, args.size)
        ratio = imp / np.maximum(geo, 1e-9)
        fmt = lambda v: " ".join(f"{x:.4f}" for x in v)  # noqa: E731
        print(
            f"{name:<20}{fmt(geo):<24}{fmt(imp):<24}{' '.join(f'{x:.3f}' for x in ratio):<20}"
            f"{spread[1] / max(spread[0], 1e-9):>8.2f}{100 * dark:>8.1f}"
        )


if __name__ == "__main__":
    t0 = time.process_time()
    main()
    print(f"({time.process_time() - t0:.0f} CPU-s)")
