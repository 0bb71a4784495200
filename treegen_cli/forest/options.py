"""Layout → the options every prototype is built and written with.

    make_options(layout)     # MakeOptions: the layout's joints, wind field, camera and LODs
    gltf_options(layout, "meshopt")

A layout's `defaults.profile` (mobile|web|desktop|hero, `treegen forest --profile`) and
`defaults.triangles` budget the prototypes as `treegen make` does: the profile row's LOD0
triangles, texture and impostor sizes and LOD triangle fractions (api.resolve, one source of
defaults); `triangles` wins over the profile's. The forest keeps its own joints, wind loop
and LOD switches (the layout's `max_joints`, `wind`, `lod_distances`): many trees share
one clip and one screen.
"""

from __future__ import annotations

from dataclasses import replace

from ..exchange import GltfOptions
from ..generate import DEFAULTS as GENERATE_DEFAULTS
from ..impostor import IMPOSTOR_DEFAULTS
from ..lod import LOD_DEFAULTS, pixel_size
from ..pipeline import MakeOptions
from ..rig import RigOptions
from ..wind import WindOptions
from .layout import Layout

# the make options a profile sets that a forest takes from it (the rest are the layout's)
FROM_PROFILE = ("triangles", "texture_size", "impostor_size", "lod_triangles")


def make_options(layout: Layout, error_px: float | None = None, impostor: bool = True) -> MakeOptions:
    """MakeOptions for every prototype: the layout's joint budget, the shared-field wind, and
    LOD schedules for the layout's camera (fov, width; else the make defaults) and error bound;
    with `impostor`, each prototype's impostor as its last LOD, as `treegen make` builds it;
    budgets and sizes from the layout's profile and triangles (module doc)."""
    w = layout.wind
    wind = (
        WindOptions(
            speed=w.speed,
            direction_deg=w.direction_deg,
            gust=w.gust,
            turbulence=w.turbulence,
            duration=w.duration,
            fps=w.fps,
            field_seed=w.seed,
        )
        if w.enabled
        else None
    )
    cam = layout.camera
    d = layout.defaults
    lod = replace(
        LOD_DEFAULTS,
        fov_deg=cam.fov_deg if cam else LOD_DEFAULTS.fov_deg,
        width=cam.width_px if cam else LOD_DEFAULTS.width,
        error_px=d.error_px if error_px is None else error_px,
        distances=d.lod_distances or LOD_DEFAULTS.distances,
    )
    options = MakeOptions(
        generate=replace(GENERATE_DEFAULTS, max_size=d.max_size, max_size_flag="defaults.max_size"),
        rig=RigOptions(max_joints=d.max_joints),
        wind=wind,
        lod=lod,
        impostor=replace(IMPOSTOR_DEFAULTS, distance=d.impostor_distance, flag="defaults.impostor_distance")
        if impostor
        else None,
    )
    if d.profile is None and d.triangles is None:
        return options
    from ..options import resolve
    from ..profiles import PROFILES

    row = PROFILES[d.profile] if d.profile else {}
    asked = {k: row[k] for k in FROM_PROFILE if k in row}
    if d.triangles is not None:
        asked["triangles"] = d.triangles
    made = resolve(asked, label=lambda k: f"defaults.{k}").options
    flag = "defaults.triangles" if d.triangles is not None else f"defaults.profile '{d.profile}': triangles"
    return replace(
        options,
        budget=replace(made.budget, flag=flag, ceiling=d.triangles is None),
        materials=made.materials,
        lod=lod if made.lod is None else replace(lod, triangles=made.lod.triangles),
        impostor=replace(options.impostor, cell=made.impostor.cell)  # the profile's atlas size
        if options.impostor and made.impostor
        else None,
    )


def gltf_options(layout: Layout, compress: str = "none", error_px: float | None = None) -> GltfOptions:
    """--compress for the forest's glTF: meshopt's position grids coarsen with each LOD's
    distance on the prototypes' screen (the layout's camera, else make's defaults)."""
    lod = make_options(layout, error_px).lod
    return GltfOptions(
        compress=compress,
        pixel_size=pixel_size(1.0, lod) if compress == "meshopt" and lod is not None else 0.0,
    )
