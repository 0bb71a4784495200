"""The impostor stage of `treegen make`: CPU seconds of this process (which counts llvmpipe's
render threads and is steadier than wall time on a shared machine), split into the GL atlas
pass and the PNG encoding, with the atlas's bytes, per profile.

    python bench/impostor_bench.py [--root DIR] [--profiles default,mobile,...] [species ...]

`--root` runs another checkout (e.g. `/work/main`, or a `git worktree` of an older commit) for
before/after. Each row builds the species with the profile's options (no impostor), then
times `add_impostor` RUNS times after one untimed call (imports, the GL driver's first load,
shader cache): `cpu s` is the median of the timed calls, `first` the untimed one of the
first row (what a fresh `treegen make` process pays; later rows find the driver loaded).

Measured on the shared 2-core box at load 13–16 (other sessions' work), quaking_aspen; the
default rows are four (main) and five runs, the checkouts alternated (the range of the
medians), the profile rows one or two runs:

    checkout            profile   atlas px  stage cpu s   first cpu s   albedo + normal KB
    main (fbf47de)      default   1024      0.246–0.250   0.307–0.383   569 + 546
    this change         default   1024      0.212–0.231   0.277–0.301   569 + 546
    main (fbf47de)      mobile    1024      0.211                       620 + 600
    this change         mobile    512       0.106–0.115                 180 + 180
    main (fbf47de)      web       1024      0.226                       573 + 547
    this change         web       512       0.119–0.127                 169 + 168
    main / this change  desktop   1024      0.273 / 0.224–0.249         573 + 547
    main / this change  hero      1024      0.444 / 0.364               552 + 531

The GL pass is most of the stage (0.15–0.17 s at 1024 px): llvmpipe's fragment work on the
600 leaf cards × 256 views, which grows with the views' pixels and the card count (measured:
one triangle per card, sorted cards, a smaller or nearest-sampled leaf texture each changed
it by 5 % or less; 400 cards instead of 600 save 22 % but coarsen the crown). The change
removed CPU work around it, outputs byte for byte the same: the box and the sphere from one
pass over the vertices with coordinates as rows (numpy's (V, 3).min(0) took ~12 ms, and ran
three times), the dilation as uint32 words (18 → 6 ms), one copy less per PNG and per
read-back, and the GL libraries named by soname (glcontext's find_library forked
`ldconfig -p` twice per context; ~2 ms here). The mobile and web rows halve with their
512² atlas. Left: hero's leaf atlas is decoded from its 2048² PNG only to be shrunk to 256²
(0.12 s of its 0.36).
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


def bench(name: str, profile: str | None, acc: dict) -> dict:
    """One row; `first_s` is the untimed call's CPU, a fresh process's only in the first row."""
    from treegen_cli import api
    from treegen_cli.exchange import export
    from treegen_cli.params import load_params
    from treegen_cli.pipeline import Timings, add_impostor, build_asset
    from treegen_cli.prepare import prepare

    given = {} if profile is None else {"profile": profile}
    job = api.resolve(given | {"impostor": False})
    params = load_params(ROOT / "species" / f"{name}.txt")
    timings = Timings()
    asset, tree = build_asset(params, 0, job.options, timings)
    options = replace(job.options, impostor=api.resolve(given).options.impostor)
    c0 = time.process_time()
    add_impostor(asset.lods, asset.materials, tree, options)  # imports, driver, shader cache
    first = time.process_time() - c0
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
        "atlas_px": imp.grid * imp.cell,
        "first_s": first,
        "cpu_s": med(cpu),
        "gl_s": med(gl),
        "png_s": med(png),
        "wall_s": med(wall),
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
    ap.add_argument(
        "--profiles",
        default="default",
        help="comma-separated: default (no --profile) and/or mobile, web, desktop, hero",
    )
    args = ap.parse_args()
    sys.path.insert(0, str((args.root or ROOT).resolve()))  # before treegen_cli is imported
    import treegen_cli
    from treegen_cli import impostor_render

    try:  # the PNG encoders' module since textures.py was split (--root may be older code)
        from treegen_cli import texture_png as png_module
    except ImportError:
        from treegen_cli import textures as png_module

    acc: dict[str, float] = {}
    _timed(impostor_render, "render_atlas", acc, "gl")
    for fn in ("png_bytes", "png_bytes_unfiltered"):
        _timed(png_module, fn, acc, "png")
    print(
        f"impostor stage ({Path(treegen_cli.__file__).parent.parent}), median of {RUNS}, "
        "16×16 views, CPU seconds unless wall"
    )
    print(
        f"{'species':<16}{'profile':<9}{'atlas':>6}{'first':>7}{'cpu s':>7}{'GL s':>7}{'PNG s':>7}"
        f"{'wall s':>7}{'GLB MB':>8}{'+KB':>7}{'albedo':>7}{'normal':>7}{'from m':>7}"
    )
    rows = 0
    for name in args.species:
        for profile in args.profiles.split(","):
            r = bench(name, None if profile == "default" else profile, acc)
            first = f"{r['first_s']:>7.3f}" if rows == 0 else f"{'-':>7}"  # cold only once
            rows += 1
            print(
                f"{name:<16}{profile:<9}{r['atlas_px']:>6}{first}{r['cpu_s']:>7.3f}"
                f"{r['gl_s']:>7.3f}{r['png_s']:>7.3f}{r['wall_s']:>7.3f}{r['glb_mb']:>8.2f}"
                f"{r['added_kb']:>7.0f}{r['albedo_kb']:>7.0f}{r['normal_kb']:>7.0f}{r['distance_m']:>7.0f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
