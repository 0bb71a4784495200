"""The impostor stage of `treegen make`: CPU seconds of this process (which counts llvmpipe's
render threads and is steadier than wall time on a shared machine), split into the GL atlas
pass and the PNG encoding, with the LOD stage of the same make for scale and the bytes the
impostor adds to the GLB.

    python bench/impostor_bench.py [--root DIR] [species ...]     # default: quaking_aspen

`--root` runs another checkout (e.g. a `git worktree` of an older commit) for before/after.
Measured on the shared 2-core box at load 17–23 (medians of 3 runs in one process; the two
checkouts alternated, four runs each; the range of the medians):

    checkout                    stage cpu s    GL pass      PNG          + KB on the GLB
    main (df35818)              0.40 – 0.54    0.25 – 0.36  0.08 – 0.10  1300
    this change                 0.27 – 0.30    0.18 – 0.21  0.04 – 0.05  1120

The GL pass is dominated by llvmpipe's per-triangle work on the 600 leaf cards × 256 views
(cost grows with the card count at equal leaf area); the change moves everything constant over
a leaf out of the fragment shader, samples a 256² copy of the leaf atlas, and writes the PNGs
unfiltered at zlib level 1 (the same pixels as before within the atlas comparison in
tests/test_impostor.py).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RUNS = 3


def _timed(module, name: str, acc: dict, key: str) -> None:
    """Wrap module.name so its CPU seconds add up in acc[key] (if the module has it)."""
    fn = getattr(module, name, None)
    if fn is None:
        return

    def wrapper(*args, **kwargs):
        t0 = time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            acc[key] = acc.get(key, 0.0) + time.process_time() - t0

    setattr(module, name, wrapper)


def bench(name: str) -> dict:
    from treegen_cli import api, impostor_render, textures
    from treegen_cli.exchange import export
    from treegen_cli.impostor import IMPOSTOR_DEFAULTS
    from treegen_cli.params import load_params
    from treegen_cli.pipeline import Timings, add_impostor, build_asset
    from treegen_cli.prepare import prepare

    job = api.resolve({"impostor": False})
    params = load_params(ROOT / "species" / f"{name}.txt")
    timings = Timings()
    asset, tree = build_asset(params, 0, job.options, timings)
    options = replace(job.options, impostor=IMPOSTOR_DEFAULTS)
    acc: dict[str, float] = {}
    _timed(impostor_render, "render_atlas", acc, "gl")
    for fn in ("png_bytes", "png_bytes_unfiltered"):
        _timed(textures, fn, acc, "png")
    add_impostor(asset.lods, asset.materials, tree, options)  # imports, shader cache
    wall, cpu, gl, png = [], [], [], []
    for _ in range(RUNS):
        acc.clear()
        t0, c0 = time.perf_counter(), time.process_time()
        lods, materials = add_impostor(asset.lods, asset.materials, tree, options)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        gl.append(acc.get("gl", 0.0))
        png.append(acc.get("png", 0.0))
    with_imp = prepare(replace(asset, lods=lods, materials=materials))
    imp = with_imp.lods[-1].impostor
    with tempfile.TemporaryDirectory() as tmp:
        base = export(asset, Path(tmp) / "a.glb")[0].stat().st_size
        full = export(with_imp, Path(tmp) / "b.glb")[0].stat().st_size
    med = statistics.median
    return {
        "species": name,
        "wall_s": med(wall),
        "cpu_s": med(cpu),
        "gl_s": med(gl),
        "png_s": med(png),
        "lod_s": timings.stages.get("lod", 0.0),
        "glb_mb": base / 1e6,
        "added_kb": (full - base) / 1e3,
        "albedo_kb": len(imp.albedo.png) / 1e3,
        "normal_kb": len(imp.normal_depth.png) / 1e3,
        "distance_m": lods[-1].distance,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("species", nargs="*", default=["quaking_aspen"])
    ap.add_argument("--root", type=Path, default=None, help="another treegen checkout to run")
    args = ap.parse_args()
    sys.path.insert(0, str((args.root or ROOT).resolve()))  # before treegen_cli is imported
    import treegen_cli

    print(
        f"impostor stage ({Path(treegen_cli.__file__).parent.parent}), median of {RUNS}, "
        "16×16 views × 64 px, CPU seconds unless wall"
    )
    print(
        f"{'species':<16}{'cpu s':>8}{'GL s':>8}{'PNG s':>8}{'wall s':>8}{'lod s':>8}"
        f"{'GLB MB':>8}{'+KB':>8}{'albedo':>8}{'normal':>8}{'from m':>8}"
    )
    for name in args.species:
        r = bench(name)
        print(
            f"{r['species']:<16}{r['cpu_s']:>8.3f}{r['gl_s']:>8.3f}{r['png_s']:>8.3f}"
            f"{r['wall_s']:>8.3f}{r['lod_s']:>8.3f}{r['glb_mb']:>8.2f}{r['added_kb']:>8.0f}"
            f"{r['albedo_kb']:>8.0f}{r['normal_kb']:>8.0f}{r['distance_m']:>8.0f}",
            flush=True,
        )


if __name__ == "__main__":
    main()
