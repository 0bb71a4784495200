"""`treegen forest LAYOUT -o OUT`: build a layout's trees once each and instance them
(`api.run_forest`, i.e. forest/build.py, does the work)."""

from __future__ import annotations

import json
from pathlib import Path

import click

from .. import api
from ..options import PROFILE_NAMES
from ..errors import TreegenError
from ..progress import current_reporter
from . import flags


@click.command()
@click.argument("layout", type=click.Path(path_type=Path), required=False)
@click.option(
    "-o",
    "--output",
    type=click.Path(path_type=Path),
    help="Output scene: .glb .gltf (one file, shared meshes/skins/animation data) or "
    ".usda .usdc .usdz (prototypes once, instanceable references).",
)
@click.option("--schema", is_flag=True, help="Print the layout file's JSON Schema and exit.")
@click.option(
    "--all-lods/--camera-lod",
    default=True,
    help='Every tree carries all its LODs (glTF MSFT_lod, USD "LOD" variant set) for '
    "the engine to switch as the player walks [default], or only the LOD the "
    "layout's camera needs (a baked view: smaller, in layout order).",
)
@click.option(
    "--error-px",
    type=float,
    default=None,
    help="Screen-space error bound of the key schedules, pixels [default: the "
    "layout's defaults.error_px, else 1].",
)
@flags.cluster(
    "Worker processes building the prototypes on this machine (Dask's local process "
    "scheduler) [default: one per core; 1: in this process].",
    "Build the prototypes on this Dask scheduler's workers instead [default: "
    "$DASK_SCHEDULER_ADDRESS, else on this machine].",
)
@click.option(
    "--max-trees",
    type=int,
    default=api.MAX_TREES,
    show_default=True,
    help="Refuse layouts that place more trees than this (checked before building).",
)
@click.option(
    "--compress",
    type=click.Choice(["none", "quantize", "meshopt"]),
    default="none",
    show_default=True,
    help="glTF only, as for `treegen make`: quantize = KHR_mesh_quantization, meshopt "
    "= that plus EXT_meshopt_compression (three.js/Babylon; not Godot or Unreal).",
)
@click.option(
    "--impostor/--no-impostor",
    default=True,
    show_default=True,
    help="End each tree's LODs with its impostor (crossed cards showing two views of a "
    "view atlas), as `treegen make` does.",
)
@click.option(
    "--profile",
    type=click.Choice(list(PROFILE_NAMES)),
    default=None,
    help="Budget the prototypes as `treegen make --profile` does (LOD0 triangles, texture "
    "and impostor sizes, LOD triangle fractions) [default: the layout's defaults.profile].",
)
@flags.json_flag("Print the summary as JSON.")
def forest(
    layout,
    output,
    schema,
    all_lods,
    error_px,
    workers,
    scheduler,
    max_trees,
    compress,
    impostor,
    profile,
    as_json,
):
    """Build the forest described by LAYOUT (JSON; see --schema): each distinct (species, seed)
    tree is built once and instanced; every instance carries all its LODs (--camera-lod: the
    one the layout's camera needs)."""
    if schema:
        click.echo(api.forest_schema_text().rstrip())
        return
    if layout is None:
        raise TreegenError("forest: give a LAYOUT file (or --schema)")
    if output is None:
        raise TreegenError("forest: give an output file with -o, e.g. -o forest.glb")
    flags.check_cluster(workers, scheduler)
    s = api.run_forest(
        layout,
        output,
        all_lods=all_lods,
        error_px=error_px,
        workers=workers,
        max_trees=max_trees,
        progress=current_reporter().show_progress,
        scheduler=scheduler,
        compress=compress,
        impostor=impostor,
        profile=profile,
    )
    if as_json:
        click.echo(json.dumps(s, indent=2))
        return
    lods = ", ".join(f"{k} {v}" for k, v in s["instances_per_lod"].items())
    click.echo(f"wrote {', '.join(s['files'])}  ({s['bytes'] / 1e6:.2f} MB)")
    click.echo(
        f"  {s['instances']:,} tree{'s' * (s['instances'] != 1)} from {s['prototypes']} "
        f"prototype{'s' * (s['prototypes'] != 1)}, "
        + ("each with all its LODs" if s["all_lods"] else "each with one LOD")
        + (f"; at the camera per LOD: {lods}" if s["camera"] and lods else "")
        + ("; no camera" if not s["camera"] else "")
    )
    if s["camera"]:
        w, wo = s["leaf_vertex_updates_per_frame"], s["leaf_vertex_updates_per_frame_without_lod"]
        ratio = f" ({w / wo:.1%})" if wo else ""
        click.echo(f"  leaf-vertex updates per frame at the camera: {w:,} with LOD vs {wo:,} without{ratio}")
    click.echo(
        f"  {s['seconds']:.2f} s  (prototypes {s['prototypes_s']:.2f} on {s['cluster']}, "
        f"write {s['write_s']:.2f})"
    )
