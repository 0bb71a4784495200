"""`treegen make SPECIES -o OUT`: grow, rig, animate, LOD and write one tree.

The whole path: the flags the user gave → `api.plan_make` (checks, `options.resolve`, species
file) → `api.run_make` (`pipeline.build_asset` → `exchange.export`) → the summary printed here.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import click

from .. import api
from ..progress import current_reporter
from . import flags


@click.command()
@click.argument("species")
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    required=True,
    help="Output file; the extension picks the format: .glb .gltf .usda .usdc .usdz "
    "(skinned, animated) or .obj .ply (static rest pose).",
)
@flags.use(*api.GROUPS["generate"], *flags.MAKE)
@flags.json_flag("Print a machine-readable summary (files, bytes, counts, seconds per stage).")
def make(species, output, as_json, **options):
    """Grow SPECIES (a species file, or a bundled name such as quaking_aspen: see `treegen
    species`) and write a skinned, wind-animated tree to OUTPUT."""
    t0 = time.perf_counter()
    job = api.plan_make(species, output, flags.given(options), flag="-o")
    rep = current_reporter()
    timings = rep.timings(total=job.stage_runs)
    with rep.live():
        s = api.run_make(job, timings)
    if as_json:
        click.echo(json.dumps(s, indent=2))
        return
    click.echo(f"wrote {', '.join(s['files'])}  ({s['bytes'] / 1e6:.2f} MB)")
    counts = (
        f"  {s['stems']:,} stems, {s['leaves']:,} leaves; {s['vertices']:,} vertices, "
        f"{s['triangles']:,} triangles"
    )
    if job.static:  # no skin: its joints and keys are not in the file
        click.echo("  static format: no wind or LODs")
        click.echo(counts)
    else:
        click.echo(f"{counts}; {_joints(s['joints'])}; {s['joint_keys']:,} keys ({s['keys']} frames)")
    if len(s["lods"]) > 1:
        click.echo(
            "  LODs: "
            + "; ".join(
                ("impostor from " if r["impostor"] else "")
                + f"{_metres(r['distance_m'])} m: {r['triangles']:,} tris, {_joints(r['joints'])}"
                + (f", {r['joint_keys']:,} keys" if k > 0 and r["joint_keys"] else "")
                + (
                    f" (error ≤ {r['max_error_px']:.2f} px on joint boxes)"  # info --lod: on hulls
                    if r["max_error_px"] is not None
                    else " (error unbounded: a camera there can be inside the tree)"
                    if k > 0 and r["decimated"]
                    else ""
                )
                + (
                    f" (over its budget of {r['budget']:,}: its trunks alone take more)"
                    if r.get("budget") is not None and r["triangles"] > r["budget"]
                    else ""
                )
                for k, r in enumerate(s["lods"])
            )
        )
    stages = ", ".join(f"{k} {v:.2f}" for k, v in timings.stages.items())
    click.echo(f"  {time.perf_counter() - t0:.2f} s  ({stages})")


def _metres(d: float) -> str:
    """A switch distance: decimetres, centimetres under 10 m (--lod-screen 4,3.9,3.8 printed
    two LODs "from 1.4 m")."""
    return f"{d:.1f}" if d >= 10.0 or d == 0.0 else f"{d:.2f}"


def _joints(n: int) -> str:
    return f"{n:,} joint" + ("" if n == 1 else "s")
