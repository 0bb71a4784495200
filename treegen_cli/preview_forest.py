"""`treegen preview LAYOUT.json`: the forest a layout places, seen from its camera, so a layout
can be checked by eye before it is written.

The prototypes are built as `treegen forest` builds them (forest.build_scene) and each tree is
drawn at the LOD the camera needs (the layout's camera; without one, a camera at --azimuth and
--elevation that frames every tree, whose distances pick the LODs the same way), in the rest
pose, placed by its instance's position, bearing and scale. Each tree is its own set of parts
with its own crown (drawable.crown; the renderer's sky occlusion is per crown); parts of one prototype's LOD
share their textures, uploaded once.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .axes import Z_UP_TO_Y_UP
from .asset import lod_bounds
from .drawable import Drawable, Part, crown, from_asset
from .errors import TreegenError
from .render_view import Camera, frame_points

NEAR_M = 0.1  # near plane of a layout's camera, metres
# what one preview draws at most: each tree is its own copy on the GPU (about 100 bytes a
# triangle); the 1,000-tree example at its camera is ~6.6 million
MAX_TRIANGLES = 30_000_000


def forest_view(
    path, azimuth: float, elevation: float, aspect: float, workers: int | None = None, framing=()
):
    """(Drawable, Camera, summary) of the layout at `path`: every tree at the LOD its camera
    (the layout's, else one framing the forest from `azimuth`/`elevation`) needs. `framing`:
    the flags the user gave for the framed camera, refused when the layout has its own."""
    from .forest import build_scene, load_layout
    from .forest.build import camera_lods

    layout = load_layout(path)
    if layout.camera is not None and framing:
        two = len(framing) > 1
        raise TreegenError(
            f"{path}: {' and '.join(framing)} frame{'' if two else 's'} a layout without a camera; "
            "this one sets 'camera' (its position and target give the view): leave "
            f"{'them' if two else 'it'} out, or remove 'camera' from the layout"
        )
    forest = build_scene(layout, all_lods=True, workers=workers, progress=None)
    inst = forest.instances
    pos = np.array([i.position for i in inst], float).reshape(-1, 3)
    rot = np.array([i.rotation_deg for i in inst], float)
    scale = np.array([i.scale for i in inst], float)
    proto = np.array([i.prototype for i in inst], int)
    if layout.camera is not None:
        cam = layout.camera
        camera = layout_camera(cam.position, cam.target, cam.fov_deg, aspect, pos, forest)
    else:
        camera = _framing(forest, pos, scale, proto, azimuth, elevation, aspect)
    lods, _dist = camera_lods(forest.prototypes, proto, pos, rot, scale, Z_UP_TO_Y_UP.T @ camera.eye)
    _check_size(path, forest, proto, lods)
    drawable = placed(forest, lods)
    counts = np.bincount(lods, minlength=max((len(a.lods) for a in forest.prototypes), default=1))
    summary = {
        "trees": len(inst),
        "prototypes": len(forest.prototypes),
        "trees_per_lod": [int(c) for c in counts],
        "camera": "layout" if layout.camera is not None else "framed",
    }
    return drawable, camera, summary


def bearing(camera: Camera) -> float:
    """The camera's bearing as --azimuth gives one (degrees counter-clockwise from +X, Z up,
    from the target towards the eye), so the default sun stands where it does in a tree's
    preview: 50° to the camera's left."""
    d = Z_UP_TO_Y_UP.T @ (np.asarray(camera.eye, float) - np.asarray(camera.target, float))
    return math.degrees(math.atan2(d[1], d[0]))


def _check_size(path, forest, proto: np.ndarray, lods: np.ndarray) -> None:
    """Refuse a view whose trees come to more than MAX_TRIANGLES, before any is placed."""
    per = {
        (p, k): sum(len(prim.indices) // 3 for prim in lod.primitives)
        for p, asset in enumerate(forest.prototypes)
        for k, lod in enumerate(asset.lods)
    }
    total = sum(per[(int(p), int(k))] for p, k in zip(proto, lods))
    if total > MAX_TRIANGLES:
        raise TreegenError(
            f"{path}: the trees this camera sees come to {total:,} triangles; a preview draws "
            f"at most {MAX_TRIANGLES:,} (about 4 × examples/forest_1000.json): preview part of "
            "the layout, or move its camera further off"
        )


def layout_camera(position, target, fov_x_deg: float, aspect: float, pos: np.ndarray, forest) -> Camera:
    """The layout's pinhole camera (Z up; `fov_deg` horizontal, as the LOD maths use it) as
    the preview's (Y up; vertical field of view for an image `aspect` wide)."""
    eye = Z_UP_TO_Y_UP @ np.asarray(position, float)
    look = Z_UP_TO_Y_UP @ np.asarray(target, float)
    fov_y = 2 * math.degrees(math.atan(math.tan(math.radians(fov_x_deg) / 2) / aspect))
    tallest = max((_height(a) for a in forest.prototypes), default=1.0)
    far = float(np.max(np.linalg.norm(pos - np.asarray(position, float), axis=1), initial=0.0))
    return Camera(eye=eye, target=look, near=NEAR_M, far=2 * far + 4 * tallest + 100.0, fov_deg=fov_y)


def _framing(forest, pos, scale, proto, azimuth, elevation, aspect) -> Camera:
    """A camera at (azimuth, elevation) that fits every tree's bounding box."""
    corners = []
    for p, asset in enumerate(forest.prototypes):
        lo, hi = lod_bounds(asset.lods[0])
        box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        mine = proto == p
        corners.append((pos[mine, None, :] + box[None] * scale[mine, None, None]).reshape(-1, 3))
    pts = np.concatenate(corners) if corners else np.zeros((1, 3))
    return frame_points(pts @ Z_UP_TO_Y_UP.T, azimuth, elevation, aspect=aspect)


def placed(forest, lods: np.ndarray) -> Drawable:
    """Every instance's parts at its LOD, rest pose, in world space (Y up)."""
    shapes: dict[tuple[int, int], tuple[list[Part], np.ndarray, np.ndarray]] = {}
    parts: list[Part] = []
    for inst, lod in zip(forest.instances, lods):
        key = (inst.prototype, int(lod))
        if key not in shapes:
            local = from_asset(forest.prototypes[inst.prototype], int(lod)).parts
            rigid = [(np.zeros_like(p.joints), _first_only(len(p.positions))) for p in local]
            shapes[key] = (local, rigid, *crown(local))
        local, rigid, centre, radius = shapes[key]
        turn = _turn_y_up(inst.rotation_deg)
        move = Z_UP_TO_Y_UP @ np.asarray(inst.position, float)
        own = (turn @ centre * inst.scale + move, _turned_radius(radius, inst.rotation_deg) * inst.scale)
        for part, (joints, weights) in zip(local, rigid):  # one joint, the rest pose: shared
            parts.append(
                replace(
                    part,
                    positions=(part.positions @ (turn.T * inst.scale) + move).astype(np.float32),
                    normals=(part.normals @ turn.T).astype(np.float32),
                    joints=joints,
                    weights=weights,
                    crown=own,
                )
            )
    return Drawable(parts=parts, n_joints=1, label=forest.name)


def _turn_y_up(degrees: float) -> np.ndarray:
    """A turn by `degrees` about the layout's +Z, in Y-up world space (about +Y)."""
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    z = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return Z_UP_TO_Y_UP @ z @ Z_UP_TO_Y_UP.T


def _turned_radius(radius: np.ndarray, degrees: float) -> np.ndarray:
    """The crown's half-extents (Y up) after a turn about Y: an axis-aligned box around the
    turned ellipse (exact at multiples of 90°)."""
    a = math.radians(degrees)
    c, s = abs(math.cos(a)), abs(math.sin(a))
    rx, ry, rz = radius
    return np.array([c * rx + s * rz, ry, s * rx + c * rz])


def _first_only(n: int) -> np.ndarray:
    w = np.zeros((n, 4), np.float32)
    w[:, 0] = 1.0
    return w


def _height(asset) -> float:
    lo, hi = lod_bounds(asset.lods[0])
    return float(hi[2] - lo[2])
