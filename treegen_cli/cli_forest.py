"""`treegen forest LAYOUT -o OUT`: the command body, kept out of cli.py (which only registers it)."""
from __future__ import annotations

import json
from pathlib import Path

import click

from .errors import TreegenError
from .limits import MAX_TREES


@click.command()
@click.argument("layout", type=click.Path(path_type=Path), required=False)
@click.option("-o", "--output", type=click.Path(path_type=Path),
              help="Output scene: .glb .gltf (one file, shared meshes/skins/animation data) or "
                   ".usda .usdc .usdz (prototypes once, instanceable references).")
@click.option("--schema", is_flag=True, help="Print the layout file's JSON Schema and exit.")
@click.option("--all-lods", is_flag=True,
              help="Write every LOD of every tree (MSFT_lod / UsdLod) instead of the one the "
                   "camera distance calls for.")
@click.option("--error-px", type=float, default=None,
              help="Screen-space error bound of the key schedules, pixels [default: the "
                   "layout's defaults.error_px, else 1].")
@click.option("--workers", type=int, default=None,
              help="Processes building prototypes [default: all cores].")
@click.option("--max-trees", type=int, default=MAX_TREES, show_default=True,
              help="Refuse layouts that place more trees than this (checked before building).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def forest(layout, output, schema, all_lods, error_px, workers, max_trees, as_json):
    """Build the forest described by LAYOUT (JSON; see --schema): each distinct (species, seed)
    tree is built once and instanced, each instance at the LOD its camera distance calls for."""
    from .forest import run_forest, schema_text

    if schema:
        click.echo(schema_text().rstrip())
        return
    if layout is None:
        raise TreegenError("forest: give a LAYOUT file (or --schema)")
    if output is None:
        raise TreegenError("forest: give an output file with -o, e.g. -o forest.glb")
    if workers is not None and workers < 1:
        raise TreegenError(f"--workers {workers}: must be at least 1")
    from .progress import current_reporter

    s = run_forest(layout, output, all_lods=all_lods, error_px=error_px, workers=workers,
                   max_trees=max_trees, progress=current_reporter().show_progress)
    if as_json:
        click.echo(json.dumps(s, indent=2))
        return
    lods = ", ".join(f"{k} {v}" for k, v in s["instances_per_lod"].items())
    click.echo(f"wrote {', '.join(s['files'])}  ({s['bytes'] / 1e6:.2f} MB)")
    click.echo(f"  {s['instances']} trees from {s['prototypes']} prototypes; per LOD: {lods}"
               + ("  (all LODs written)" if s["all_lods"] else ""))
    w, wo = s["leaf_vertex_updates_per_frame"], s["leaf_vertex_updates_per_frame_without_lod"]
    ratio = f" ({w / wo:.1%})" if wo else ""
    click.echo(f"  leaf-vertex updates per frame: {w:,} with LOD vs {wo:,} without{ratio}")
    click.echo(f"  {s['seconds']:.2f} s  (prototypes {s['prototypes_s']:.2f}, "
               f"write {s['write_s']:.2f})")
