"""What a renderer draws, whatever it came from: skinned parts in Y-up world space plus a way to
pose them (`skinning(t)`: per-joint matrices S_j(t) = W_j(t)·B_j⁻¹, as an engine uploads).

Built from an in-memory Asset here, or from a written file by the exchange readers (glTF,
UsdSkel), so the preview and the tests see exactly what a file's skin and animation do.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .asset import IMPOSTOR_MATERIAL, TWIGS
from .axes import Z_UP_TO_Y_UP, to_y_up
from .clip import sample_track
from .errors import TreegenError
from .skeleton import forward, trs


@dataclass(frozen=True, eq=False)
class Part:
    """One skinned triangle list with one material (Y up)."""

    name: str
    positions: np.ndarray  # float32 (V, 3), rest pose
    normals: np.ndarray  # float32 (V, 3)
    indices: np.ndarray  # uint32 (T*3,)
    joints: np.ndarray  # (V, 4) ints, into the scene's skinning matrices
    weights: np.ndarray  # float32 (V, 4)
    color: tuple[float, float, float]  # linear base colour (multiplies `texture`)
    double_sided: bool = False  # leaves: lit from both faces, light passes through
    uvs: np.ndarray | None = None  # float32 (V, 2), origin bottom-left (OpenGL/USD)
    texture: np.ndarray | None = None  # uint8 (H, W, 4) sRGB colour + straight alpha, top row first
    normal_map: np.ndarray | None = None  # uint8 (H, W, 3) tangent space, +Y = +v (OpenGL/glTF)
    normal_scale: float = 1.0  # glTF normalTexture.scale: strength of the bumps
    alpha_cutoff: float | None = None  # cut-out: discard where alpha < this (None: opaque)
    opacity: float = 1.0  # base colour alpha factor (multiplies texture alpha)
    wrap: tuple[str, str] = ("REPEAT", "REPEAT")  # texture's (u, v): REPEAT CLAMP MIRROR
    normal_wrap: tuple[str, str] = ("REPEAT", "REPEAT")  # normal map's (u, v)
    impostor: bool = False  # cards showing a view atlas's views (asset.IMPOSTOR_MATERIAL)
    # (centre, half-extents) of the crown this part belongs to, where a drawable holds many
    # trees (a forest preview); None: the drawable's one crown (render.Renderer)
    crown: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def receives_shadows(self) -> bool:
        """Impostor cards cast the sun's shadow but take none, as engines set up billboard/
        impostor LODs (Unity's receiveShadows off, Godot's shadows-not-received flag, three.js's
        default): their shading is in the atlas, and two crossed cards would otherwise shade
        each other's far half as a solid wedge."""
        return not self.impostor

    @property
    def one_sided(self) -> bool:
        """Single-sided cut-out cards (the impostor's back-to-back twins) get their back faces
        culled, as engines do; closed, opaque bark is drawn both ways as always."""
        return not self.double_sided and self.alpha_cutoff is not None

    @property
    def textured(self) -> bool:
        return self.uvs is not None and self.texture is not None

    @property
    def bumpy(self) -> bool:
        return self.uvs is not None and self.normal_map is not None


WRAPS = ("REPEAT", "CLAMP", "MIRROR")


def lit_through(name: str | None, double_sided: bool) -> bool:
    """Whether a part is foliage (Part.double_sided: lit from both faces, light passing
    through): a double-sided material's, but not a far LOD's crossed bark ribbons
    (mesh.TWIGS), which are bark seen from either side."""
    return bool(double_sided) and name != TWIGS


def crown(parts: list[Part]) -> tuple[np.ndarray, np.ndarray]:
    """Centre and half-extents (at least a twentieth of the whole tree's size) of the box
    around the leaves' rest positions, or around every vertex of a leafless tree: the volume
    whose depth dims a vertex's sky light in the preview (Part.crown, render.Renderer)."""
    pts = [p.positions for p in parts if len(p.positions)]
    allp = np.concatenate(pts).astype(np.float64) if pts else np.zeros((1, 3))
    leaves = [p.positions for p in parts if p.double_sided and len(p.positions)]
    box = np.concatenate(leaves).astype(np.float64) if leaves else allp
    lo, hi = box.min(0), box.max(0)
    size = max(float(np.max(allp.max(0) - allp.min(0))), 1e-3)
    return 0.5 * (lo + hi), np.maximum(0.5 * (hi - lo), 0.05 * size)


def decode_image(data: bytes, channels: int, what: str = "texture") -> np.ndarray:
    """PNG/JPEG/WebP bytes → uint8 (H, W, channels), top row first (Pillow; any mode in)."""
    import io

    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(data)) as src:
            img = src.convert("RGBA" if channels == 4 else "RGB")
            return np.asarray(img, dtype=np.uint8).copy()
    except (UnidentifiedImageError, OSError, ValueError) as e:
        raise TreegenError(f"{what}: not a readable image ({type(e).__name__}: {e})") from None


@dataclass(frozen=True, eq=False)
class Drawable:
    """What to draw: parts plus a way to pose them. `skinning(t)` gives (T, J, 4, 4) matrices
    (column-vector, Y up) for times t in seconds; None means the rest pose (identities)."""

    parts: list[Part]
    n_joints: int
    duration: float = 0.0  # wind loop length, s (0: static)
    skinning: Callable[[np.ndarray], np.ndarray] | None = None
    label: str = ""

    def pose(self, t: np.ndarray) -> np.ndarray:
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        if self.skinning is None:
            return np.broadcast_to(np.eye(4), (len(t), self.n_joints, 4, 4)).copy()
        return self.skinning(t)


def is_impostor(material: str | None) -> bool:
    """Whether a part with this material is the impostor's cards (Part.impostor)."""
    return material == IMPOSTOR_MATERIAL


def z_up_to_y_up() -> np.ndarray:
    """4×4 Z-up → Y-up change of axes (axes.Z_UP_TO_Y_UP, the glTF convention)."""
    c = np.eye(4)
    c[:3, :3] = Z_UP_TO_Y_UP
    return c


@dataclass(frozen=True, eq=False)
class Channel:
    """One animated property of some joints, all on the same key times."""

    joints: np.ndarray  # (M,) joint indices
    path: str  # "rotation" | "translation" | "scale"
    times: np.ndarray  # (K,) seconds
    values: np.ndarray  # (K, M, 4 or 3)
    interpolation: str = "LINEAR"


@dataclass(frozen=True, eq=False)
class PoseRig:
    """Enough of a skeleton to pose it: rest TRS per joint, the world matrix above each root
    joint, inverse binds and channels. `to_world` maps the source's axes to Y up."""

    parent: np.ndarray  # (J,) −1 where the parent is not a joint
    translation: np.ndarray  # (J, 3)
    rotation: np.ndarray  # (J, 4) xyzw
    scale: np.ndarray  # (J, 3)
    root_world: np.ndarray  # (J, 4, 4): world of the non-joint parent (identity if none)
    inverse_bind: np.ndarray  # (J, 4, 4)
    channels: list[Channel] = field(default_factory=list)
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))

    @property
    def duration(self) -> float:
        return max((float(c.times[-1]) for c in self.channels if len(c.times)), default=0.0)

    def skinning(self, t: np.ndarray) -> np.ndarray:
        """(T, J, 4, 4) skinning matrices in Y-up world space at times t."""
        t = np.atleast_1d(np.asarray(t, dtype=np.float64))
        T, J = len(t), len(self.parent)
        pose = {
            "translation": np.broadcast_to(self.translation, (T, J, 3)).copy(),
            "rotation": np.broadcast_to(self.rotation, (T, J, 4)).copy(),
            "scale": np.broadcast_to(self.scale, (T, J, 3)).copy(),
        }
        for c in self.channels:
            pose[c.path][:, c.joints] = sample_track(
                c.times, c.values, t, c.interpolation, rotation=c.path == "rotation"
            )
        local = trs(pose["translation"], pose["rotation"], pose["scale"])
        world = forward(self.parent, local, self.root_world)
        skin = world @ self.inverse_bind
        return self.to_world @ skin @ self.to_world.T


def from_asset(asset, lod: int = 0, label: str = "") -> Drawable:
    """An in-memory Asset (generator space, Z up) as a Drawable."""
    check_lod(lod, len(asset.lods), label or asset.name)
    L = asset.lods[lod]
    mats = {m.name: m for m in asset.materials}
    parts = []
    decoded: dict[int, np.ndarray] = {}  # a Texture shared by materials is decoded once

    def image(tex, channels):
        if tex is None:
            return None
        key = (id(tex), channels)
        if key not in decoded:
            decoded[key] = decode_image(tex.png, channels, f"{asset.name}: texture {tex.name!r}")
        return decoded[key]

    for p in L.primitives:
        m = mats.get(p.material)
        uvs = getattr(p, "uvs", None)
        has_uv = uvs is not None and len(uvs) == len(p.positions)
        base = m.base_texture if m and has_uv else None
        normal = m.normal_texture if m and has_uv else None
        parts.append(
            Part(
                name=p.name,
                positions=to_y_up(p.positions).astype(np.float32),
                normals=to_y_up(p.normals).astype(np.float32),
                indices=np.asarray(p.indices, np.uint32),
                joints=np.asarray(p.joints),
                weights=np.asarray(p.weights, np.float32),
                color=tuple(m.base_color[:3]) if m else (0.6, 0.6, 0.6),
                double_sided=lit_through(p.material, bool(m and m.double_sided)),
                uvs=np.asarray(uvs, np.float32) if has_uv else None,
                texture=image(base, 4),
                normal_map=image(normal, 3),
                alpha_cutoff=m.alpha_cutoff if m else None,
                opacity=float(m.base_color[3]) if m and len(m.base_color) > 3 else 1.0,
                wrap=_wrap(base),
                normal_wrap=_wrap(normal),
                impostor=is_impostor(p.material),
            )
        )
    sk = L.skeleton
    J = len(sk.names)
    channels = []
    if L.clips:
        clip = L.clips[0]
        rot = np.asarray(clip.rotations, dtype=np.float64)
        if clip.keys is None:
            channels.append(
                Channel(np.arange(J), "rotation", np.asarray(clip.times), rot, clip.interpolation)
            )
        else:
            for j, keys in enumerate(clip.keys):  # joints (hundreds), each its own schedule
                keys = np.asarray(keys, dtype=np.int64)
                channels.append(
                    Channel(
                        np.array([j]),
                        "rotation",
                        np.asarray(clip.times)[keys],
                        rot[keys, j : j + 1],
                        clip.interpolation,
                    )
                )
    rig = PoseRig(
        parent=np.asarray(sk.parent),
        translation=np.asarray(sk.rest_translation),
        rotation=np.asarray(sk.rest_rotation),
        scale=np.ones((J, 3)),
        root_world=np.broadcast_to(np.eye(4), (J, 4, 4)),
        inverse_bind=sk.inverse_bind(),
        channels=channels,
        to_world=z_up_to_y_up(),
    )
    return Drawable(
        parts=parts,
        n_joints=J,
        duration=rig.duration,
        skinning=rig.skinning if channels else None,
        label=label or asset.name,
    )


def _wrap(tex) -> tuple[str, str]:
    w = getattr(tex, "wrap", "REPEAT") if tex is not None else "REPEAT"
    w = w if w in WRAPS else "REPEAT"
    return (w, w)


def check_lod(lod: int, n: int, what) -> None:
    if not 0 <= lod < n:
        have = f"LODs 0..{n - 1}" if n > 1 else "only LOD 0"
        raise TreegenError(f"{what}: --lod {lod} is out of range; this asset has {have}")


def forest_error(path, instances: int) -> TreegenError:
    """The one line for a forest file handed to a single-tree reader: drawing its first tree (or
    failing to find a tree outside its instances) would say nothing true about the file."""
    return TreegenError(
        f"{path}: a forest ({instances} instance{'s' * (instances != 1)}); preview draws single "
        f"trees: preview one of "
        f"its species (treegen preview SPECIES) or a tree from treegen make SPECIES -o tree.glb"
    )


def vertex_normals(pos: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals, for meshes that come without any."""
    tri = np.asarray(idx, np.int64).reshape(-1, 3)
    p = np.asarray(pos, np.float64)
    fn = np.cross(p[tri[:, 1]] - p[tri[:, 0]], p[tri[:, 2]] - p[tri[:, 0]])
    n = np.zeros_like(p)
    for k in range(3):
        np.add.at(n, tri[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.where(length > 0, length, 1.0)).astype(np.float32)
