"""How a written file describes its impostor atlas (glTF `asset.extras.treegen_impostor`, USD
layer metadata, and the sidecar `tree.glb.impostor.json`): one dict, in the file's own axes.

No glTF or USD convention for impostors exists, so the description says everything an impostor
shader needs: the layout and its formula, the sphere each view frames, the frame the directions
and normals are expressed in, and what each image channel holds (see README, "Impostor").
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..asset import Asset

ENCODING = (
    "d: unit vector from centre towards the viewer; n = (d·a, d·b, d·up) with up >= 0; "
    "s = |n.x| + |n.y| + n.z; p = (n.x / s, n.y / s); "
    "u = (p.x + p.y) / 2 + 0.5; v = (p.y - p.x) / 2 + 0.5 (v from the image's top); "
    "cell = (floor(u * grid), floor(v * grid)) as (column, row)"
)
DECODING = (
    "cell centre (u, v) = ((column + 0.5) / grid, (row + 0.5) / grid); p = (u - v, u + v - 1); "
    "d = normalize(p.x * a + p.y * b + (1 - |p.x| - |p.y|) * up)"
)
VIEW = (
    "orthographic; right = normalize(cross(up, d)) (b if d = up), up' = cross(d, right); "
    "cell pixel (x, y) in [-1, 1]^2, y towards the cell's top, shows centre + radius * (x * right + y * up')"
)


def impostor_lod(asset: Asset) -> int | None:
    """Index of the asset's impostor LOD (the last one that has an atlas), or None."""
    found = [k for k, lod in enumerate(asset.lods) if lod.impostor is not None]
    return found[-1] if found else None


def describe(asset: Asset, k: int, to_file: np.ndarray, images: dict) -> dict:
    """The description of LOD k's impostor; `to_file` (3, 3) maps generator vectors (Z up)
    to the file's axes; `images`: where the albedo and normal_depth images are (glTF image
    indices, or file names relative to the main file)."""
    lod = asset.lods[k]
    imp = lod.impostor
    assert imp is not None, f"LOD {k} has no impostor"
    m = np.asarray(to_file, np.float64)

    def vec(v) -> list[float]:
        return [float(round(x, 6)) + 0.0 for x in m @ np.asarray(v, np.float64)]

    lo, hi = (m @ imp.bounds[0], m @ imp.bounds[1])
    return {
        "version": 1,
        "layout": "hemi-octahedral",
        "hemisphere": True,
        "grid": int(imp.grid),
        "cell_px": int(imp.cell),
        "atlas_px": [int(imp.grid * imp.cell)] * 2,
        "centre": vec(imp.centre),
        "radius": float(imp.radius),
        "bounds_min": [float(x) for x in np.minimum(lo, hi)],
        "bounds_max": [float(x) for x in np.maximum(lo, hi)],
        "axes": {"a": vec((1, 0, 0)), "b": vec((0, 1, 0)), "up": vec((0, 0, 1))},
        "encoding": ENCODING,
        "decoding": DECODING,
        "view": VIEW,
        "images": images,
        "albedo": "sRGB colour with the crown's self-shading baked in (leaves x 0.37 / 0.40 / 0.59 in "
        f"r / g / b; inner crown darker); alpha = coverage, cut out below "
        f"{imp.alpha_cutoff:g}",
        "normal_depth": "rgb = unit normal in (a, b, up) * 0.5 + 0.5 (linear); "
        "alpha = 0.5 + 0.5 * dot(p - centre, d) / radius (1 towards the viewer)",
        "cards": [[int(c), int(r)] for c, r in imp.cards],
        "cards_receive_shadows": False,  # crossed cards would shade each other in a wedge
        "lod_index": int(asset.extras.get("lod_index", k)),
        "distance_m": float(lod.distance),
    }


def sidecar_path(path: Path) -> Path:
    """`tree.glb` → `tree.glb.impostor.json`: the format in the name, as a tree written as
    .glb and .usdc into one folder has two different descriptions (axes, image references)."""
    return path.with_name(path.name + ".impostor.json")


def write_sidecar(meta: dict, path: Path) -> None:
    sidecar_path(path).write_text(json.dumps(meta, indent=1, sort_keys=True) + "\n")
