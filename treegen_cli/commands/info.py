"""`treegen info SPECIES`: grow a tree and report on it (`api.info` computes, this prints)."""

from __future__ import annotations

import json

import click

from .. import api
from . import flags


@click.command()
@click.argument("species")
@flags.use(*api.GROUPS["generate"])
@flags.json_flag("Print the summary as JSON.")
@click.option(
    "--lod",
    "with_lod",
    is_flag=True,
    help="Also build the LODs and print, per LOD distance, keys kept, max error, leaf-"
    "vertex updates per frame vs all leaf vertices, joints, triangles.",
)
@flags.use(*api.GROUPS["lod"], *api.INFO_LOD_BUILD)
@click.option(
    "--wind",
    "with_wind",
    is_flag=True,
    help="Also print the wind physics: natural frequencies and damping, the trunk's "
    "sway frequency, and the tree top's lean and sway at --wind-speed.",
)
@flags.use(
    "wind_speed",
    "stiffness",
    help={
        "stiffness": "Multiplier on every joint's stiffness and the root plate's (frequencies "
        "scale with about its square root)."
    },
)
@flags.use(
    "triangles",
    help={
        "triangles": "Also plan a LOD0 triangle budget as `make --triangles N` would, and print "
        "the levers it picks and the triangles it will build."
    },
)
def info(species, as_json, with_lod, with_wind, triangles, **options):
    """Grow SPECIES (a Weber–Penn text or Arbaro XML file, or a bundled name such as
    quaking_aspen: see `treegen species`) and report on the tree:
    stems per level, leaves, leaf area (m²), height and crown width (m), nodes, seconds.
    With --lod: one row per LOD, and the analogue of the paper's Table 3: the full tree's
    clip at the paper's 30 m and 130 m under the bounded and the paper's schedule, side by side.
    With --wind: the wind model's numbers, to tune --wind-speed, --gust and --stiffness."""
    stats = api.info(species, lod=with_lod, wind=with_wind, triangles=triangles, **flags.given(options))
    if as_json:
        click.echo(json.dumps(stats, indent=2))
        return
    o = options
    budget = stats["triangles"].get("budget")
    grown = "" if budget is None or budget["as_is"] else "; as grown: `make` builds the budget's tree, below"
    click.echo(f"{stats['species']}  ({stats['file']}, seed {o['seed']}{grown})")
    rows = [
        (
            "stems",
            f"{stats['stems']:,}  per level {stats['stems_per_level']}  ({stats['clones']:,} split clones)",
        ),
        ("nodes", f"{stats['nodes']:,}"),
        ("leaves", f"{stats['leaves']:,}"),
        ("leaf area", f"{stats['leaf_area_m2']:.2f} m²"),
        ("height", f"{stats['height_m']:.2f} m"),
        ("crown width", f"{stats['crown_width_m']:.2f} m"),
        ("trunk radius", f"{stats['trunk_radius_m'] * 100:.1f} cm"),
        ("generation", f"{stats['generate_s']:.3f} s"),
        (
            "triangles",
            f"{stats['triangles']['lod0']:,} at LOD0 ({stats['triangles']['bark']:,} "
            f"bark, {stats['triangles']['leaves']:,} leaves)",
        ),
    ]
    if "budget" in stats["triangles"]:
        b = stats["triangles"]["budget"]
        whose = "" if triangles is not None else f" (the {o['profile']} profile's)"
        rows.append(
            (
                "budget",
                f"--triangles {b['target']:,}{whose}: {b['plan']}"
                + ("" if b["as_is"] else f"; the fewest it reaches: {b['minimum']:,}"),
            )
        )
    for name, value in rows:
        click.echo(f"  {name:<13}{value}")
    if with_lod:
        _lod_table(stats, o)
    if with_wind:
        _wind_lines(stats["wind"], o)


def _lod_table(stats: dict, o: dict) -> None:
    click.echo(
        f"  LODs (fov {o['fov']:g}°, {o['width']} px, error {o['error_px']:g} px, "
        f"{o['schedule']}): max err measured on every joint's hull corners (make prints the "
        "bound on its boxes, a little higher); leaf-vertex updates per frame, LOD method vs all-GPU"
    )
    click.echo(
        f"    {'LOD':<4}{'dist m':>8}{'keys kept':>16}{'max err px':>11}"
        f"{'updates/frame':>15}{'leaf verts':>12}{'joints':>8}{'triangles':>11}"
    )
    for k, r in enumerate(stats["lods"]):
        click.echo(
            f"    {k:<4}{r['distance_m']:>8.1f}{r['keys_kept']:>9,} {r['keys_kept_pct']:>5.1f}%"
            f"{r['max_error_px']:>11.3f}{r['leaf_vertex_updates_per_frame']:>15,.0f}"
            f"{r['leaf_vertices']:>12,}{r['joints']:>8}{r['triangles']:>11,}"
        )
        if "impostor" in r:
            i = r["impostor"]
            click.echo(
                f"    LOD {k} is the impostor: from {r['distance_m']:.1f} m, two crossed "
                f"cards {i['card_m']:.1f} m square showing two of {i['grid']}×{i['grid']} views "
                f"of {i['cell_px']} px ({i['atlas_px']}² atlas, "
                f"{i['atlas_bytes'] / 1e3:,.0f} KB of PNG), drawn at {i['card_view_px']} px"
            )
    click.echo(
        "  schedules on the full tree (the paper's Table 3; error: perspective-true, "
        "measured on every vertex's bound)"
    )
    click.echo(
        f"    {'dist m':>6}  {'schedule':<9}{'keys kept':>16}{'anim bytes':>12}"
        f"{'max err px':>11}{'updates/frame':>15}"
    )
    for r in stats["schedules"]:
        click.echo(
            f"    {r['distance_m']:>6g}  {r['schedule']:<9}{r['keys_kept']:>9,} "
            f"{r['keys_kept_pct']:>5.1f}%{r['animation_bytes']:>12,}"
            f"{r['max_error_px']:>11.3f}{r['leaf_vertex_updates_per_frame']:>15,.0f}"
        )


def _wind_lines(w: dict, o: dict) -> None:
    click.echo(f"  wind ({o['wind_speed']:g} m/s, stiffness ×{o['stiffness']:g}):")
    click.echo(
        "    modes        " + ", ".join(f"{m['hz']:.2f} Hz (ζ {m['damping']:.2f})" for m in w["modes"])
    )
    if w["sway_hz"] is not None:
        click.echo(
            f"    crown sway   {w['sway_hz']:.3f} Hz (its motion's peak), damping ζ {w['sway_damping']:.2f}"
        )
        click.echo(
            f"    tree top     leans {w['top_lean_m']:.2f} m downwind, sways "
            f"{w['top_sway_rms_m']:.2f} m RMS; largest joint turn {w['max_joint_deg']:.1f}°"
        )
