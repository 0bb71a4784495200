"""The preview's view maths, no GL: look-at, perspective and orthographic matrices, the
direction of a viewer at (azimuth, elevation), a camera that frames a set of points, and
linear blend skinning on the CPU (for framing the animated tree). World space is Y up."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FOV_DEG = 30.0  # vertical field of view of the preview camera


def skin_points(
    points: np.ndarray, joints: np.ndarray, weights: np.ndarray, skinning: np.ndarray
) -> np.ndarray:
    """Linear blend skinning on the CPU: Σ_k w_k · S[j_k] · p for (V, 3) points and (J, 4, 4)
    matrices. Used for framing (animated bounds) and as the reference for the shader."""
    p = np.asarray(points, dtype=np.float64)
    out = np.zeros_like(p)
    for k in range(joints.shape[1]):  # four influence slots, not vertices
        m = skinning[np.asarray(joints[:, k], dtype=np.int64)]
        out += weights[:, k, None] * (np.einsum("vij,vj->vi", m[:, :3, :3], p) + m[:, :3, 3])
    return out


def look_at(eye: np.ndarray, target: np.ndarray, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    f = np.asarray(target, float) - eye
    f /= np.linalg.norm(f)
    r = np.cross(f, up)
    if np.linalg.norm(r) < 1e-9:
        r = np.cross(f, (0.0, 0.0, 1.0))
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = r, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def perspective(fov_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / np.tan(np.radians(fov_deg) / 2)
    m = np.zeros((4, 4))
    m[0, 0], m[1, 1] = f / aspect, f
    m[2, 2], m[2, 3] = (far + near) / (near - far), 2 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def orthographic(half: float, near: float, far: float) -> np.ndarray:
    m = np.eye(4)
    m[0, 0] = m[1, 1] = 1.0 / half
    m[2, 2], m[2, 3] = -2.0 / (far - near), -(far + near) / (far - near)
    return m


def direction(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """Unit vector (Y up) from the tree towards the viewer. Azimuth is measured in the
    generator's Z-up frame, counter-clockwise from +X (so 0 looks from +X, -90 from −Y)."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    zx, zy, zz = np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)
    return np.array([zx, zz, -zy])  # Z up → Y up: (x, y, z) → (x, z, −y)


@dataclass(frozen=True)
class Camera:
    eye: np.ndarray
    target: np.ndarray
    near: float
    far: float
    fov_deg: float = FOV_DEG

    def view_proj(self, aspect: float = 1.0) -> np.ndarray:
        return perspective(self.fov_deg, aspect, self.near, self.far) @ look_at(self.eye, self.target)


def frame_points(
    points: np.ndarray,
    azimuth_deg: float,
    elevation_deg: float,
    margin: float = 0.08,
    fov_deg: float = FOV_DEG,
    aspect: float = 1.0,
) -> Camera:
    """A camera looking from (azimuth, elevation) that fits every point inside a view `aspect`
    (width / height) wide with `margin` (fraction of each half-extent) to spare, centred on the
    points' screen extent. `fov_deg` is vertical, so the view's half-width is aspect times its
    half-height: fitting both to the height alone cropped a tall tree's crown in a portrait view."""
    pts = np.asarray(points, dtype=np.float64)
    lo, hi = pts.min(0), pts.max(0)
    target = 0.5 * (lo + hi)
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-3)
    back = direction(azimuth_deg, elevation_deg)
    tan_half = np.tan(np.radians(fov_deg) / 2) * (1.0 - margin)  # vertical
    tan_wide = tan_half * aspect  # horizontal
    dist = 3.0 * radius
    for _ in range(4):  # fit distance, re-centre on the projected extent, fit again
        view = look_at(target + back * dist, target)
        v = pts @ view[:3, :3].T + view[:3, 3]  # camera space, looking down −z
        depth = -v[:, 2]
        x, y = v[:, 0] / depth, v[:, 1] / depth  # tangents of the view angles
        cx, cy = 0.5 * (x.min() + x.max()), 0.5 * (y.min() + y.max())
        right, up = view[0, :3], view[1, :3]
        target = target + dist * (cx * right + cy * up)
        # distance at which every point's x and y tangents from the new centre fit the view
        rel = pts - target
        along = rel @ back  # towards the camera
        lateral = np.maximum(np.abs(rel @ right) / tan_wide, np.abs(rel @ up) / tan_half)
        dist = float(np.max(along + lateral))
    eye = target + back * dist
    near = min(max(dist - radius * 1.5, dist * 0.02), ground_depth(eye, back, up, lo[1], fov_deg))
    return Camera(eye=eye, target=target, near=near, far=dist + radius * 60)


def ground_depth(eye: np.ndarray, back: np.ndarray, up: np.ndarray, ground_y: float, fov_deg: float) -> float:
    """Nine tenths of the view depth at which the image's bottom edge meets the ground plane
    (inf if it looks above it). A view framed to the width (a portrait image) reaches well
    below the tree's foot, and a near plane set by the tree alone cut the ground there, leaving
    a band of sky along the bottom. The camera has no roll, so the whole edge meets the ground
    at one depth."""
    down = np.tan(np.radians(fov_deg) / 2) * up[1] + back[1]  # −y of the ray at depth 1
    height = float(eye[1] - ground_y)
    if down <= 1e-9 or height <= 0:
        return float("inf")
    return 0.9 * height / float(down)
