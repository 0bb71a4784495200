"""Layout file → placed instances → shared prototypes → one animated scene to walk through.

Result: `treegen forest layout.json -o forest.glb` writes every distinct (species, seed) tree
once (a prototype, built on Dask, with whatever LODs the pipeline gives it) and places it many
times; each instance carries all its prototype's LODs for the engine to switch, or, with
`--camera-lod`, only the one its distance to the layout's camera calls for.

    layout = load_layout("examples/forest_30m.json")      # validated; TreegenError names the
    forest = build_scene(layout, workers=2)               #   JSON path, e.g. instances[12].species
    export_forest(forest, "forest.glb")                   # atomic (exchange)

One module per job: schema.py (the published JSON Schema and its checker), layout.py (file →
placements), scatter.py (placing trees in a region), build.py (prototypes on Dask, order or
camera LOD and phase per instance, the summary, the whole command).
"""

from __future__ import annotations

from .build import build_prototypes, build_scene, gltf_options, run_forest, select_lod, summary, time_offsets
from .layout import Camera, Defaults, Layout, Placement, WindSpec, load_layout, parse_layout
from .scatter import inside_polygon, polygon_area, scatter_points
from .schema import check_schema, layout_schema, schema_text

__all__ = [
    "Camera",
    "Defaults",
    "Layout",
    "Placement",
    "WindSpec",
    "build_prototypes",
    "build_scene",
    "check_schema",
    "gltf_options",
    "inside_polygon",
    "layout_schema",
    "load_layout",
    "parse_layout",
    "polygon_area",
    "run_forest",
    "scatter_points",
    "schema_text",
    "select_lod",
    "summary",
    "time_offsets",
]
