"""File sizes of `--compress none / quantize / meshopt` against gltfpack on the same input.

    python bench/size_bench.py [--species quaking_aspen,black_tupelo] [--sets default]

For the four Weber–Penn paper species × each option set (OPTION_SETS; `--profile NAME` rows
appear when `treegen make` has that option): LOD0 triangles and joints, the GLB's bytes
without compression, with `quantize` and `meshopt`, and gltfpack's (npm `gltfpack`, pinned in
tools/) on the uncompressed file: its default (quantized) and `-cc -af 0` (meshopt, keys
kept), with the ratios ours / gltfpack. Targets: quantize ≤ gltfpack default, meshopt ≤
gltfpack -cc -af 0. Each tree is built once and written three ways.

`err q / m` is how far LOD0's animation moves any skinned vertex from the float file's on any
frame in our quantize / meshopt files (mm; key_plan.py's measure on hull corners;
bound 1 mm). `tracks` is LOD0's rotation tracks in ours / with more than one key in
gltfpack's default output: gltfpack drops or collapses to one key every track it finds nearly
still, including ones whose motion moves the geometry by millimetres (beyond the 1 mm LOD0
bound), which is where a ratio above 1 comes from.

Measured 2026-11-26 (2-core box under load; MB; the last line counts bytes, not the rounded
ratios):

    species        set        none  quant     gp  q/gp meshopt gp -cc  m/gp  err q/m mm
    quaking_aspen  default   13.76   8.80   9.05 0.973    3.60   3.79 0.951  0.69/0.88
    quaking_aspen  mobile     2.82   1.85   1.91 0.969    0.94   0.97 0.960  0.61/0.85
    quaking_aspen  web        7.38   4.69   4.81 0.975    1.91   2.04 0.938  0.84/0.85
    black_tupelo   default   32.94  20.98  21.25 0.987    6.76   7.28 0.929  0.80/0.86
    black_tupelo   mobile     2.66   1.77   1.82 0.972    0.96   0.97 0.987  0.74/0.86
    black_tupelo   web        7.46   4.45   4.54 0.979    2.08   2.09 0.994  0.86/0.88
    weeping_willow default  259.13 165.68 165.85 0.999   40.64  47.50 0.856  0.94/0.90
    weeping_willow mobile     3.06   2.15   2.18 0.989    1.19   1.23 0.967  0.86/0.91
    weeping_willow web        7.88   5.22   5.29 0.986    2.16   2.26 0.954  0.86/0.88
    ca_black_oak   default   40.15  25.04  24.92 1.005    7.65   8.21 0.932  0.97/0.88
    ca_black_oak   mobile     2.49   1.62   1.59 1.018    0.80   0.80 0.999  0.97/0.94
    ca_black_oak   web        7.82   4.72   4.67 1.012    2.04   2.10 0.972  0.97/0.90
    quantize <= gltfpack: 9 of 12 rows; meshopt <= gltfpack -cc -af 0: 12 of 12

(before aimed keys, still lower-LOD tracks and one-bit filter steps, the same day: 9 and 9.)
"""

from __future__ import annotations

import argparse
import subprocess
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from treegen_cli import api, key_plan
from treegen_cli.exchange import export
from treegen_cli.exchange.gltf_container import read_gltf
from treegen_cli.params import load_params
from treegen_cli.pipeline import Timings

ROOT = Path(__file__).resolve().parent.parent
SPECIES = ("quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak")
GLTFPACK = ROOT / "tools" / "node_modules" / ".bin" / "gltfpack"
# name → make options; profiles join when `--profile` exists (api.DEFAULTS["profile"])
OPTION_SETS: dict[str, dict] = {"default": {}}
for _profile in ("mobile", "web"):
    if "profile" in api.DEFAULTS:
        OPTION_SETS[_profile] = {"profile": _profile}


def gltfpack(src: Path, dst: Path, *flags: str) -> int:
    subprocess.run([str(GLTFPACK), "-i", str(src), "-o", str(dst), *flags], check=True, capture_output=True)
    return dst.stat().st_size


def moving_tracks(path: Path) -> int:
    """Channels of the file's `wind_loop` (LOD0's clip) whose sampler has more than one key."""
    gltf, _ = read_gltf(path)
    anim = next((a for a in gltf.get("animations", []) if a.get("name") == "wind_loop"), None)
    if anim is None:
        return 0
    return sum(
        gltf["accessors"][anim["samplers"][c["sampler"]]["output"]]["count"] > 1 for c in anim["channels"]
    )


def row(name: str, set_name: str, options: dict, tmp: Path) -> dict:
    params = load_params(ROOT / "species" / f"{name}.txt")
    base = api.resolve({**options, "compress": "none"}, output="x.glb")
    asset, tree = api.build(params, name, base, Timings())
    asset = replace(asset, up_axis=base.values["up_axis"])
    out: dict = {
        "species": name,
        "set": set_name,
        "triangles": sum(len(p.indices) // 3 for p in asset.lods[0].primitives),
        "joints": len(asset.lods[0].skeleton.names),
    }
    for compress in ("none", "quantize", "meshopt"):
        job = api.resolve({**options, "compress": compress}, output="x.glb")
        path = tmp / f"{name}_{set_name}_{compress}.glb"
        t0 = time.perf_counter()
        export(asset, path, job.options.gltf)
        out[compress] = path.stat().st_size
        out[f"{compress}_s"] = time.perf_counter() - t0
    lod0 = asset.lods[0]
    for compress in ("quantize", "meshopt"):
        kp = key_plan.plan(lod0, lod0.clips[0], compress == "meshopt")
        out[f"{compress}_err"] = key_plan.error(lod0, lod0.clips[0], kp)
    src = tmp / f"{name}_{set_name}_none.glb"
    out["gp"] = gltfpack(src, tmp / "gp.glb")
    out["tracks"], out["gp_tracks"] = moving_tracks(src), moving_tracks(tmp / "gp.glb")
    out["gp_cc"] = gltfpack(src, tmp / "gp_cc.glb", "-cc", "-af", "0")
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--species", default=",".join(SPECIES))
    ap.add_argument("--sets", default=",".join(OPTION_SETS))
    args = ap.parse_args()
    if not GLTFPACK.exists():
        raise SystemExit(f"{GLTFPACK} missing: run make install (cd tools && npm ci)")
    mb = 1e6
    print(
        f"{'species':<16}{'set':<9}{'tris':>9}{'joints':>7}{'none MB':>9}{'quant MB':>9}"
        f"{'gp MB':>8}{'q/gp':>6}{'meshopt':>9}{'gp -cc':>8}{'m/gp':>6}{'none/m':>7}"
        f"{'err q/m mm':>11}{'tracks':>10}"
    )
    met_q = met_m = rows = 0
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.species.split(","):
            for set_name in args.sets.split(","):
                r = row(name, set_name, OPTION_SETS[set_name], Path(tmp))
                rows += 1
                met_q += r["quantize"] <= r["gp"]
                met_m += r["meshopt"] <= r["gp_cc"]
                print(
                    f"{name:<16}{set_name:<9}{r['triangles']:>9,}{r['joints']:>7}"
                    f"{r['none'] / mb:>9.2f}{r['quantize'] / mb:>9.2f}{r['gp'] / mb:>8.2f}"
                    f"{r['quantize'] / r['gp']:>6.3f}{r['meshopt'] / mb:>9.2f}"
                    f"{r['gp_cc'] / mb:>8.2f}{r['meshopt'] / r['gp_cc']:>6.3f}"
                    f"{r['none'] / r['meshopt']:>7.1f}"
                    f"{r['quantize_err'] * 1e3:>6.2f}/{r['meshopt_err'] * 1e3:<4.2f}"
                    f"{r['tracks']:>5}/{r['gp_tracks']:<4}",
                    flush=True,
                )
    print(
        f"quantize <= gltfpack: {met_q} of {rows} rows; meshopt <= gltfpack -cc -af 0: {met_m} of {rows} (bytes)"
    )


if __name__ == "__main__":
    main()
