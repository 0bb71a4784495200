"""The `treegen` command line. Thin: parse options, call the pipeline, report.

Every user mistake arrives here as a TreegenError and leaves as one line on stderr, exit 2.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import click

from . import __version__
from .errors import TreegenError, in_file as _in_file
from .generate import GenerateOptions

# a species file or a bundled name (bundled.resolve_species: an existing path wins)
SPECIES = click.STRING


def _generate_options(f):
    f = click.option("--max-size", type=float, default=GenerateOptions.max_size, show_default=True,
                     metavar="METRES",
                     help="Refuse trees taller, or with a crown wider, than this many metres: a "
                          "plausibility bound that catches a mistyped Scale (the tallest living "
                          "tree is about 116 m); raise it for giants on purpose.")(f)
    f = click.option("--max-leaves", type=int, default=GenerateOptions.max_leaves, show_default=True,
                     help="Refuse trees with more leaves than this (estimated before growing).")(f)
    f = click.option("--max-stems", type=int, default=GenerateOptions.max_stems, show_default=True,
                     help="Refuse trees with more stems than this (estimated before growing).")(f)
    f = click.option("--seed", type=int, default=0, show_default=True,
                     help="Random seed: the same seed grows the same tree, byte for byte.")(f)
    return f


def _lod_options(f):
    """--lod-screen, --lod-distances, --fov, --width, --error-px, --schedule (lod.py)."""
    f = click.option("--schedule", type=click.Choice(["bounded", "bounded-step", "paper"]),
                     default="bounded", show_default=True,
                     help="Key schedule per LOD. bounded: slerp between kept keys, every vertex "
                     "within --error-px on a perspective screen seen from any direction at the "
                     "LOD's switch distance; bounded-step: the same bound with keys held; paper: "
                     "the paper's accumulate-and-reset rule as written (P/d > i·tan(fov)/width, "
                     "held), unchecked.")(f)
    f = click.option("--error-px", type=float, default=1.0, show_default=True,
                     help="Allowed on-screen error in pixels (the paper's i); 0 keeps every key.")(f)
    f = click.option("--width", type=int, default=1920, show_default=True,
                     help="Screen width in pixels.")(f)
    f = click.option("--fov", type=float, default=60.0, show_default=True,
                     help="Horizontal field of view, degrees (16:9 screen).")(f)
    f = click.option("--lod-distances", default=None, metavar="0,10,30,130",
                     help="Force the metres from which each LOD is used, from the centre of the "
                     "tree's bounds (LOD0 first; at 0 it keeps the dense clip). Replaces "
                     "--lod-screen.")(f)
    f = click.option("--lod-screen", default="0.5,0.25,0.1", show_default=True, metavar="0.5,0.25,0.1",
                     help="LOD1, LOD2, … take over when the tree's height falls below these "
                     "fractions of the screen height (distances per tree from its height and "
                     "--fov).")(f)
    return f


def _lod_options_from(lod_screen, lod_distances, fov, width, error_px, schedule):
    """LodOptions from the LOD flags, validated as `make` validates them (api.resolve)."""
    from .api import resolve

    return resolve(dict(lod_screen=lod_screen, lod_distances=lod_distances, fov=fov, width=width,
                        error_px=error_px, schedule=schedule)).options.lod


def _species(value: str) -> Path:
    from .bundled import resolve_species
    return resolve_species(value)


def _load(species: Path):
    from .params import load_params
    return load_params(species)


def _given(values: dict) -> dict:
    """The options the user gave (not click defaults), so a --profile fills only the rest:
    resolve() applies the profile, then the defaults, to what is missing."""
    from click.core import ParameterSource

    ctx = click.get_current_context()
    return {k: v for k, v in values.items()
            if ctx.get_parameter_source(k) not in (ParameterSource.DEFAULT, None)}


@click.group(context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="treegen")
def cli():
    """Grow Weber–Penn trees and write them skinned, wind-animated and LOD'd for game engines."""


@cli.command()
@click.argument("species", type=SPECIES)
@_generate_options
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--lod", "with_lod", is_flag=True,
              help="Also build the LODs and print, per LOD distance, keys kept, max error, leaf-"
                   "vertex updates per frame vs all leaf vertices, joints, triangles.")
@_lod_options
@click.option("--wind", "with_wind", is_flag=True,
              help="Also print the wind physics: natural frequencies and damping, the trunk's "
                   "sway frequency, and the tree top's lean and sway at --wind-speed.")
@click.option("--wind-speed", type=float, default=4.0, show_default=True, help="Mean wind speed, m/s.")
@click.option("--stiffness", type=float, default=1.0, show_default=True,
              help="Multiplier on every joint's stiffness (frequencies scale with its square root).")
@click.option("--triangles", type=int, default=None, metavar="N",
              help="Also plan a LOD0 triangle budget as `make --triangles N` would, and print "
                   "the levers it picks and the triangles it will build.")
def info(species, seed, max_stems, max_leaves, max_size, as_json, with_lod, lod_screen,
         lod_distances, fov, width, error_px, schedule, with_wind, wind_speed, stiffness, triangles):
    """Grow SPECIES (a Weber–Penn text or Arbaro XML file, or a bundled name such as
    quaking_aspen: see `treegen species`) and report on the tree:
    stems per level, leaves, leaf area (m²), height and crown width (m), nodes, seconds.
    With --lod: one row per LOD, and the analogue of the paper's Table 3: the full tree's
    clip at the paper's 30 m and 130 m under the bounded and the paper's schedule, side by side.
    With --wind: the wind model's numbers, to tune --wind-speed, --gust and --stiffness."""
    from .api import resolve
    from .generate import generate
    from .tree import tree_stats

    generate_options = resolve(dict(seed=seed, max_stems=max_stems, max_leaves=max_leaves,
                                    max_size=max_size)).options.generate
    species = _species(species)
    params = _load(species)
    t0 = time.perf_counter()
    tree = _in_file(species, generate, params, seed, generate_options)
    seconds = time.perf_counter() - t0
    from .progress import current_reporter
    current_reporter().detail(f"  generate  {seconds:8.3f} s  ({tree.n_stems:,} stems, "
                              f"{tree.n_nodes:,} nodes, {tree.n_leaves:,} leaves)")
    stats = tree_stats(tree) | {"generate_s": round(seconds, 4), "file": str(species)}
    stats["triangles"] = _triangle_rows(species, params, seed, tree, triangles,
                                        generate_options)
    if with_lod:
        lod_options = _lod_options_from(lod_screen, lod_distances, fov, width, error_px, schedule)
        stats["lods"], stats["schedules"] = _lod_rows(
            species, params, seed, tree, generate_options,
            lod_options)
    if with_wind:
        from .rig import build_rig
        from .wind import wind_report
        wind = resolve(dict(wind_speed=wind_speed, stiffness=stiffness)).options.wind
        stats["wind"] = wind_report(tree, build_rig(tree), wind, seed)
    if as_json:
        click.echo(json.dumps(stats, indent=2))
        return
    click.echo(f"{stats['species']}  ({species}, seed {seed})")
    rows = [
        ("stems", f"{stats['stems']:,}  per level {stats['stems_per_level']}"
                  f"  ({stats['clones']:,} split clones)"),
        ("nodes", f"{stats['nodes']:,}"),
        ("leaves", f"{stats['leaves']:,}"),
        ("leaf area", f"{stats['leaf_area_m2']:.2f} m²"),
        ("height", f"{stats['height_m']:.2f} m"),
        ("crown width", f"{stats['crown_width_m']:.2f} m"),
        ("trunk radius", f"{stats['trunk_radius_m'] * 100:.1f} cm"),
        ("generation", f"{seconds:.3f} s"),
        ("triangles", f"{stats['triangles']['lod0']:,} at LOD0 ({stats['triangles']['bark']:,} "
                      f"bark, {stats['triangles']['leaves']:,} leaves)"),
    ]
    if "budget" in stats["triangles"]:
        b = stats["triangles"]["budget"]
        rows.append(("budget", f"--triangles {triangles:,}: {b['plan']}; the fewest it "
                               f"reaches: {b['minimum']:,}"))
    for name, value in rows:
        click.echo(f"  {name:<13}{value}")
    if with_lod:
        click.echo(f"  LODs (fov {fov:g}°, {width} px, error {error_px:g} px, {schedule}): "
                   "leaf-vertex updates per frame, LOD method vs all-GPU")
        click.echo(f"    {'LOD':<4}{'dist m':>8}{'keys kept':>16}{'max err px':>11}"
                   f"{'updates/frame':>15}{'leaf verts':>12}{'joints':>8}{'triangles':>11}")
        for k, r in enumerate(stats["lods"]):
            click.echo(f"    {k:<4}{r['distance_m']:>8g}{r['keys_kept']:>9,} {r['keys_kept_pct']:>5.1f}%"
                       f"{r['max_error_px']:>11.3f}{r['leaf_vertex_updates_per_frame']:>15,.0f}"
                       f"{r['leaf_vertices']:>12,}{r['joints']:>8}{r['triangles']:>11,}")
            if "impostor" in r:
                i = r["impostor"]
                click.echo(f"    LOD {k} is the impostor: from {r['distance_m']:g} m, two crossed "
                           f"cards {i['card_m']:g} m square cut from {i['grid']}×{i['grid']} views "
                           f"of {i['cell_px']} px ({i['atlas_px']}² atlas, "
                           f"{i['atlas_bytes'] / 1e3:,.0f} KB of PNG)")
        click.echo("  schedules on the full tree (the paper's Table 3; error: perspective-true, "
                   "measured on every vertex's bound)")
        click.echo(f"    {'dist m':>6}  {'schedule':<9}{'keys kept':>16}{'anim bytes':>12}"
                   f"{'max err px':>11}{'updates/frame':>15}")
        for r in stats["schedules"]:
            click.echo(f"    {r['distance_m']:>6g}  {r['schedule']:<9}{r['keys_kept']:>9,} "
                       f"{r['keys_kept_pct']:>5.1f}%{r['animation_bytes']:>12,}"
                       f"{r['max_error_px']:>11.3f}{r['leaf_vertex_updates_per_frame']:>15,.0f}")
    if with_wind:
        w = stats["wind"]
        click.echo(f"  wind ({wind_speed:g} m/s, stiffness ×{stiffness:g}):")
        click.echo("    modes        " + ", ".join(f"{m['hz']:.2f} Hz (ζ {m['damping']:.2f})"
                                                  for m in w["modes"]))
        if w["sway_hz"] is not None:
            click.echo(f"    trunk sway   {w['sway_hz']:.3f} Hz, damping ζ {w['sway_damping']:.2f}")
            click.echo(f"    tree top     leans {w['top_lean_m']:.2f} m downwind, sways "
                       f"{w['top_sway_rms_m']:.2f} m RMS; largest joint turn {w['max_joint_deg']:.1f}°")


def _triangle_rows(species, params, seed, tree, triangles, generate_options) -> dict:
    """LOD0 triangles as `make` builds the grown tree (exact, from its stems and leaves), and
    with a budget the plan `make --triangles` would build."""
    from .budget import BudgetOptions, plan_budget
    from .limits import estimate_triangles
    from .mesh import MESH_DEFAULTS

    bark, leaves = estimate_triangles(tree, MESH_DEFAULTS)
    out: dict = {"lod0": bark + leaves, "bark": bark, "leaves": leaves}
    if triangles is not None:
        plan = _in_file(species, plan_budget, params, seed, MESH_DEFAULTS,
                        BudgetOptions(triangles=triangles), generate_options)
        out["budget"] = {"triangles": plan.triangles, "bark": plan.bark, "leaves": plan.leaves,
                         "levels": plan.levels, "curve_scale": plan.curve_scale,
                         "sides": list(plan.mesh.sides),
                         "rings_per_segment": list(plan.mesh.rings_per_segment),
                         "leaf_quality_factor": round(plan.leaf_factor, 6),
                         "minimum": plan.minimum, "maximum": plan.maximum,
                         "plan": plan.describe()}
    return out


def _lod_rows(species, params, seed, tree, generate_options, lod_options) -> tuple[list, list]:
    """Rows per LOD (the make pipeline with these LOD options, on the tree `info` already grew,
    measured per LOD), and the full tree's schedules side by side at the paper's distances."""
    from .impostor import IMPOSTOR_DEFAULTS
    from .lod import PAPER_DISTANCES, lod_table_row, schedule_rows
    from .pipeline import MakeOptions, Timings, build_asset
    from .render import egl_available

    options = MakeOptions(generate=generate_options, lod=lod_options,      # as `make` builds it
                          impostor=IMPOSTOR_DEFAULTS if egl_available() else None)
    asset, _tree = _in_file(species, build_asset, params, seed, options, Timings(), tree)
    return ([lod_table_row(lod, lod_options) for lod in asset.lods],
            schedule_rows(asset.lods[0], PAPER_DISTANCES, lod_options))


@cli.command()
@click.argument("species", type=SPECIES)
@click.option("-o", "--output", type=click.Path(path_type=Path), required=True,
              help="Output file; the extension picks the format: .glb .gltf .usda .usdc .usdz "
                   "(skinned, animated) or .obj .ply (static rest pose).")
@_generate_options
@click.option("--max-joints", type=int, default=256, show_default=True,
              help="Joint budget of the skeleton (>= 1); chains coarsen and the finest levels "
                   "lose their joints first.")
@click.option("--joints", type=int, default=None, metavar="N",
              help="Joint budget: --max-joints by a shorter name.")
@click.option("--triangles", type=int, default=None, metavar="N",
              help="LOD0 triangle budget, met from 10 % under to N by the generator's own levers (fewer, "
                   "larger leaves of the same area; fewer sides, segments and stem levels), or "
                   "refused naming the fewest the species reaches [default: the species as is].")
@click.option("--profile", type=click.Choice(["mobile", "web", "desktop", "hero"]), default=None,
              help="Preset triangles, joints, texture size, clip length, fps and LOD distances "
                   "for a platform (README table); options you give win over it.")
@click.option("--joint-levels", default=None, metavar="0,1,2",
              help="Stem levels allowed to own joints [default: all].")
@click.option("--sides", default=None, metavar="16,8,6,4,3",
              help="Cross-section sides per stem level, trunk first; the last value repeats "
                   "[default: 16,8,6,4,3].")
@click.option("--leaf-geometry", type=click.Choice(["card", "shape"]), default="card",
              show_default=True,
              help="card: one textured quad per leaf (the leaf outline belongs in the texture's "
                   "alpha); shape: the species' LeafShape outline as geometry.")
@click.option("--texture-size", type=int, default=512, show_default=True,
              help="Leaf atlas side in texels, a power of two in [64, 2048]; bark maps are half.")
@click.option("--leaf-texture", type=click.Path(path_type=Path), default=None, metavar="FILE.png",
              help="Your own leaf image (PNG, alpha = cut-out), embedded as is; each card maps "
                   "to the whole image [default: generated from the species].")
@click.option("--bark-texture", type=click.Path(path_type=Path), default=None, metavar="FILE.png",
              help="Your own tileable bark image (PNG), embedded as is, wrapping once around "
                   "every stem [default: generated albedo + normal map].")
@click.option("--no-textures", is_flag=True, help="Colour-only materials (species colours).")
@click.option("--wind-speed", type=float, default=4.0, show_default=True, help="Mean wind speed, m/s.")
@click.option("--wind-dir", type=float, default=0.0, show_default=True,
              help="Direction the wind blows towards, degrees (0 = +X, 90 = +Y in Z-up terms).")
@click.option("--gust", type=float, default=0.35, show_default=True,
              help="Gust intensity: σ of the gust process / mean speed.")
@click.option("--turbulence", type=float, default=0.3, show_default=True,
              help="Spatially varying turbulence: σ / mean speed.")
@click.option("--duration", type=float, default=10.0, show_default=True,
              help="Clip length in seconds (the wind loops over it).")
@click.option("--fps", type=float, default=30.0, show_default=True, help="Keys per second.")
@click.option("--stiffness", type=float, default=1.0, show_default=True,
              help="Multiplier on every joint's stiffness: 4 doubles the sway frequencies and "
                   "roughly quarters the motion (see `treegen info --wind`).")
@click.option("--no-wind", is_flag=True, help="Write no animation (rest pose only).")
@click.option("--up-axis", type=click.Choice(["y", "z"]), default=None,
              help="Up axis of USD, OBJ and PLY files, metres either way [default: y for .usdz "
                   ".obj .ply, z for .usda .usdc]; glTF is always Y up.")
@_lod_options
@click.option("--lod-triangles", default="0.5,0.15,0.05", show_default=True, metavar="0.5,0.15,0.05",
              help="Triangles of LOD1, LOD2, … as fractions of LOD0's (the last repeats); a LOD "
                   "never has more than the one before it. Each is cut from LOD0's tree: fewer "
                   "sides, stems thinner than half a pixel at its distance dropped, fewer leaves "
                   "spread over the whole crown and scaled to cover what all of them covered.")
@click.option("--no-lod", is_flag=True, help="Write one LOD with the dense clip.")
@click.option("--lod-files", is_flag=True,
              help="Write each LOD as its own complete file, NAME_LOD0.glb, NAME_LOD1.glb, … "
                   "(for engines that ignore MSFT_lod: Godot, Unity LODGroup, Unreal).")
@click.option("--impostor/--no-impostor", default=True, show_default=True,
              help="End the LODs with an impostor: crossed cards cut from a 16×16-view "
                   "hemi-octahedral atlas (albedo, normals + depth; described in the file's "
                   "extras and NAME.glb.impostor.json), swaying with the trunk.")
@click.option("--compress", type=click.Choice(["none", "quantize", "meshopt"]), default="none",
              show_default=True,
              help="glTF only: quantize = KHR_mesh_quantization (integer positions, normals, "
                   "UVs, rotations); meshopt = that plus EXT_meshopt_compression (needs the "
                   "client's meshopt decoder). Both are required extensions; none is read by "
                   "every importer.")
@click.option("--max-vertices", type=int, default=20_000_000, show_default=True,
              help="Refuse meshes with more vertices than this per LOD (counted from the grown "
                   "tree before the mesh is built).")
@click.option("--max-keys", type=int, default=5_000_000, show_default=True,
              help="Refuse wind clips with more joint-keys (joints × keys) than this.")
@click.option("--json", "as_json", is_flag=True,
              help="Print a machine-readable summary (files, bytes, counts, seconds per stage).")
def make(species, output, seed, max_stems, max_leaves, max_size, max_joints, joints, triangles, profile,
         joint_levels, sides,
         leaf_geometry, texture_size, leaf_texture, bark_texture, no_textures, wind_speed,
         wind_dir, gust, turbulence, duration, fps, stiffness, no_wind, up_axis, lod_screen,
         lod_distances, fov, width, error_px, schedule, lod_triangles, no_lod, lod_files,
         impostor, compress, max_vertices, max_keys, as_json):
    """Grow SPECIES (a species file, or a bundled name such as quaking_aspen: see `treegen
    species`) and write a skinned, wind-animated tree to OUTPUT."""
    from .api import build, check_output, resolve, write
    from .exchange import STATIC
    from .progress import current_reporter
    from .tree import tree_stats

    t0 = time.perf_counter()
    check_output(output, up_axis, flag="-o")
    job = resolve(_given(dict(seed=seed, max_stems=max_stems, max_leaves=max_leaves, max_size=max_size,
                       max_joints=max_joints, joints=joints, triangles=triangles,
                       profile=profile, joint_levels=joint_levels, sides=sides,
                       leaf_geometry=leaf_geometry, texture_size=texture_size,
                       leaf_texture=leaf_texture, bark_texture=bark_texture,
                       no_textures=no_textures, wind_speed=wind_speed, wind_dir=wind_dir,
                       gust=gust, turbulence=turbulence, duration=duration, fps=fps,
                       stiffness=stiffness, no_wind=no_wind, lod_screen=lod_screen,
                       lod_distances=lod_distances, fov=fov, width=width, error_px=error_px,
                       schedule=schedule, lod_triangles=lod_triangles,
                       no_lod=no_lod, lod_files=lod_files, impostor=impostor, compress=compress,
                       up_axis=up_axis, max_vertices=max_vertices, max_keys=max_keys)),
                  output=output)
    options = job.options
    static = output.suffix.lower() in STATIC
    params = _load(_species(species))
    rep = current_reporter()
    per_lod = 3 if options.wind is None else 5          # generate, rig, mesh (, wind, lod)
    timings = rep.timings(total=per_lod + 3 if options.lod is None else
                          options.lod.count * per_lod + 3   # (+ materials, prepare, write)
                          + (options.impostor is not None))           # (+ impostor)
    with rep.live():
        asset, tree = build(params, species, job, timings)
        s = write(asset, tree, output, timings, t0, job)
    per_level = tree_stats(tree)["stems_per_level"]
    rep.detail(f"  counts    stems per level {per_level}, {tree.n_nodes:,} nodes, "
               f"{tree.n_leaves:,} leaves, {len(asset.lods)} LOD(s)")
    if as_json:
        click.echo(json.dumps(s, indent=2))
        return
    click.echo(f"wrote {', '.join(s['files'])}  ({s['bytes'] / 1e6:.2f} MB)")
    if static:
        click.echo("  static format: no wind or LODs")
    click.echo(f"  {s['stems']:,} stems, {s['leaves']:,} leaves; {s['vertices']:,} vertices, "
               f"{s['triangles']:,} triangles; {s['joints']} joints; {s['keys']} keys")
    if len(s["lods"]) > 1:
        click.echo("  LODs: " + "; ".join(
            f"{r['distance_m']:g} m: {r['triangles']:,} tris, {r['joints']} joints"
            + (f", {r['joint_keys']:,} keys" if r["decimated"] else "") for r in s["lods"]))
    stages = ", ".join(f"{k} {v:.2f}" for k, v in timings.stages.items())
    click.echo(f"  {time.perf_counter() - t0:.2f} s  ({stages})")


from .cli_forest import forest  # noqa: E402  (its body lives in cli_forest.py)
from .cli_batch import batch  # noqa: E402  (its body lives in cli_batch.py)

cli.add_command(forest)
cli.add_command(batch)

from .preview import preview_command  # noqa: E402  (body in preview.py)
from .species_list import species_command  # noqa: E402  (body in species_list.py)

cli.add_command(preview_command)
cli.add_command(species_command)


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the CLI, turning user errors into one line and exit code 2."""
    from .progress import add_output_options

    add_output_options(cli)     # -q/--quiet, -v/--verbose on every registered command
    try:
        cli.main(args=argv, prog_name="treegen", standalone_mode=False)
    except TreegenError as e:
        click.echo(f"treegen: error: {e}", err=True)
        sys.exit(2)
    except click.exceptions.Abort:
        click.echo("treegen: aborted", err=True)
        sys.exit(130)
    except click.ClickException as e:
        e.show()
        sys.exit(e.exit_code)
    except click.exceptions.Exit as e:
        sys.exit(e.exit_code)
    sys.exit(0)
