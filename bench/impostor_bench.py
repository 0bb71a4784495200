"""The impostor stage on the default aspen: seconds (wall and this process's CPU, which counts
llvmpipe's render threads and is steadier on a shared machine), with the LOD stage of the
same make for scale, and the bytes the impostor adds to the GLB.

    python bench/impostor_bench.py [species ...]      # default: quaking_aspen
"""
from __future__ import annotations

import statistics
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

from treegen_cli import api
from treegen_cli.exchange import export
from treegen_cli.impostor import IMPOSTOR_DEFAULTS
from treegen_cli.params import load_params
from treegen_cli.pipeline import Timings, add_impostor, build_asset
from treegen_cli.prepare import prepare

ROOT = Path(__file__).resolve().parent.parent
RUNS = 3


def bench(name: str) -> dict:
    job = api.resolve({"impostor": False})
    params = load_params(ROOT / "species" / f"{name}.txt")
    timings = Timings()
    asset, tree = build_asset(params, 0, job.options, timings)
    options = replace(job.options, impostor=IMPOSTOR_DEFAULTS)
    wall, cpu = [], []
    for _ in range(RUNS):
        t0, c0 = time.perf_counter(), time.process_time()
        lods, materials = add_impostor(asset.lods, asset.materials, tree, options)
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    with_imp = prepare(replace(asset, lods=lods, materials=materials))
    imp = with_imp.lods[-1].impostor
    with tempfile.TemporaryDirectory() as tmp:
        base = export(asset, Path(tmp) / "a.glb")[0].stat().st_size
        full = export(with_imp, Path(tmp) / "b.glb")[0].stat().st_size
    return {"species": name, "wall_s": statistics.median(wall), "cpu_s": statistics.median(cpu),
            "lod_s": timings.stages.get("lod", 0.0), "glb_mb": base / 1e6,
            "added_kb": (full - base) / 1e3, "albedo_kb": len(imp.albedo.png) / 1e3,
            "normal_kb": len(imp.normal_depth.png) / 1e3, "distance_m": lods[-1].distance}


def main(names: list[str]) -> None:
    print(f"impostor stage, median of {RUNS} (16×16 views × 64 px, one batched GL pass)")
    print(f"{'species':<16}{'wall s':>8}{'cpu s':>8}{'lod s':>8}{'GLB MB':>8}{'+KB':>8}"
          f"{'albedo':>8}{'normal':>8}{'from m':>8}")
    for name in names:
        r = bench(name)
        print(f"{r['species']:<16}{r['wall_s']:>8.3f}{r['cpu_s']:>8.3f}{r['lod_s']:>8.3f}"
              f"{r['glb_mb']:>8.2f}{r['added_kb']:>8.0f}{r['albedo_kb']:>8.0f}"
              f"{r['normal_kb']:>8.0f}{r['distance_m']:>8.0f}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["quaking_aspen"])
