"""What writers receive: a finished, format-neutral asset (a tree, or a forest of instanced
trees). Writers only serialise it: whatever they need beyond the stages' output (moving
joints, animated bounds, the shared timeline USD keys on, phase-shifted and repeated clips)
is filled in by prepare.py before any writer sees it.

Everything is in generator space (metres, Z up, right-handed); each writer converts to its
format's axes (glTF: Y up). Quaternions are (x, y, z, w), scipy's order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Texture:
    """An image a material samples, already encoded (PNG bytes, deterministic)."""

    name: str  # file stem when written beside a file: "leaf", "bark", "bark_normal"
    png: bytes
    wrap: str = "REPEAT"  # "REPEAT" (bark: tiles) or "CLAMP" (leaf atlas cells)
    srgb: bool = True  # colour data (sRGB) or raw data (normal maps)


@dataclass(frozen=True)
class Material:
    name: str  # "bark" / "leaf"
    base_color: tuple[float, float, float, float]  # linear RGBA; multiplies base_texture
    roughness: float = 0.9
    metallic: float = 0.0
    double_sided: bool = False
    alpha_cutoff: float | None = None  # alpha-tested cut-out (MASK) below this alpha
    base_texture: Texture | None = None  # sRGB colour (+ alpha for cut-outs)
    normal_texture: Texture | None = None  # tangent space, OpenGL/glTF convention (+Y up)


@dataclass(frozen=True, eq=False)
class Primitive:
    """One triangle list with one material, skinned to the LOD's skeleton."""

    name: str  # "bark" / "leaves"
    material: str  # Material.name
    positions: np.ndarray  # float32 (V, 3), rest pose, generator space
    normals: np.ndarray  # float32 (V, 3), unit
    uvs: np.ndarray  # float32 (V, 2)
    indices: np.ndarray  # uint32 (T*3,), counter-clockwise front faces
    joints: np.ndarray  # uint16 (V, 4), indices into Skeleton joints
    weights: np.ndarray  # float32 (V, 4), rows sum to 1, unused slots 0
    flat_normals: bool = False  # True: every vertex normal is the face normal of
    # each triangle using it (planar leaf cards), so a
    # writer may omit normals (glTF clients then compute
    # exactly these flat normals)
    tangents: np.ndarray | None = None  # float32 (V, 4) for normal-mapped primitives (bark, impostor cards):
    # xyz unit, along +u, orthogonal to the normal; w = ±1
    # with w·cross(normal, xyz) along +v (up in the image),
    # glTF's TANGENT convention


@dataclass(frozen=True, eq=False)
class Skeleton:
    """Joints ordered parent-before-child; joint 0 is the root at the trunk base."""

    names: list[str]  # unique, path-safe ("j0", "j1", ...)
    parent: np.ndarray  # int32 (J,), -1 for the root
    rest_translation: np.ndarray  # float64 (J, 3), local (in the parent's frame)
    rest_rotation: np.ndarray  # float64 (J, 4), local quaternion xyzw
    bind_world: np.ndarray  # float64 (J, 4, 4), world matrix of each joint at
    # rest (rigid); inverse bind matrix = inv(bind_world)

    def inverse_bind(self) -> np.ndarray:
        """inv(bind_world) (J, 4, 4) as the rigid inverse [Rᵀ | −Rᵀt], in elementwise arithmetic:
        LAPACK's inverse picks CPU-specific kernels, so its last bits (and the file's bytes)
        would differ from machine to machine."""
        m = np.asarray(self.bind_world, dtype=np.float64)
        rt = np.swapaxes(m[:, :3, :3], 1, 2)
        out = np.zeros_like(m)
        out[:, :3, :3] = rt
        out[:, :3, 3] = -(rt * m[:, None, :3, 3]).sum(axis=2)
        out[:, 3, 3] = 1.0
        return out


@dataclass(frozen=True, eq=False)
class Clip:
    """Baked joint rotations. `keys[j]` selects which of `times` joint j keeps (LOD schedule);
    None keeps every key. Translations and scales stay at rest."""

    name: str  # "wind_loop", "wind_lod1_loop", ...
    times: np.ndarray  # float64 (K,), seconds, starts at 0
    rotations: np.ndarray  # float64 (K, J, 4), local quaternions xyzw
    interpolation: str = "LINEAR"  # "LINEAR" or "STEP"
    keys: list[np.ndarray] | None = None  # per joint: sorted int indices into times
    animated: np.ndarray | None = None  # bool (J,): joints that get a channel (None: all
    # joints whose rotation ever leaves rest)
    timeline: tuple[np.ndarray, np.ndarray] | None = None
    # prepared: (frames (U,), rotations (U, M, 4)) of the
    # animated joints (the root if none) keyed together at
    # the union of their kept keys, each playing its own
    # track (formats with one time list per animation)
    plan: KeyPlan | None = None  # a compressed file's keys, bits and float32 joints
    # (key_plan.with_key_plans; None: every kept key as it is)
    error_px: float | None = None  # decimated: the kept keys' worst on-screen error, pixels
    # from the LOD's distance (lod_decimate: the joints' box corners, an upper bound on every
    # vertex; the "bounded" schedules keep it ≤ error_px, the paper's walk does not)


# meshopt's EXPONENTIAL filter: bits of mantissa kept for a KeyPlan's float32 (`wide`) joints
# (steps of 2^(1 − bits) on a unit quaternion, 2^(2 − bits) where a component is ±1); the
# writer encodes with it, key_codec.exp_filter models it to the bit
EXP_BITS = 20


@dataclass(frozen=True)
class KeyPlan:
    """A dense clip as a compressed file stores it: `clip` with per-joint kept keys, `wide`
    (J,) joints whose keys stay float32, and under meshopt the QUATERNION filter's `bits`
    (J,) of the others (None: int16, quantize)."""

    clip: Clip
    wide: np.ndarray
    bits: np.ndarray | None = None


# The impostor cards' material. Its crown shading is baked into the atlas, so the cards cast
# shadows but receive none (drawable.Part.receives_shadows): crossed cards in a shadow map
# would darken each other in a sharp wedge, as the preview showed before.
IMPOSTOR_MATERIAL = "impostor"
# The primitive and material of a far LOD's thin branches drawn as two crossed ribbons
# (mesh/ribbons.py): the bark's texture on both faces, lit as bark (drawable.lit_through).
TWIGS = "twigs"


@dataclass(frozen=True, eq=False)
class Impostor:
    """The view atlas behind an impostor LOD (impostor.py): grid × grid orthographic views of
    the sphere (centre, radius) on a hemi-octahedral layout, for engines with impostor shaders.
    Generator space; the writers state it in their file's axes."""

    albedo: Texture  # sRGB + coverage alpha (also the cards' texture)
    normal_depth: Texture  # rgb: (a, b, up) normal · 0.5 + 0.5; a: depth
    grid: int  # views per side
    cell: int  # pixels per view
    centre: np.ndarray  # (3,) metres
    radius: float
    bounds: tuple[np.ndarray, np.ndarray]  # rest-pose (min, max) of the geometry rendered
    cards: tuple[tuple[int, int], ...] = ()  # (column, row) of the cells the cards show
    alpha_cutoff: float = 0.5


@dataclass(frozen=True, eq=False)
class Lod:
    primitives: list[Primitive]
    skeleton: Skeleton
    clips: list[Clip] = field(default_factory=list)
    distance: float = 0.0  # metres from which this LOD is used
    screen_coverage: float = 1.0  # MSFT_screencoverage hint (fraction of screen height)
    bounds: tuple[np.ndarray, np.ndarray] | None = None
    # prepared: (min, max) of the skinned geometry at rest
    # and at every key of every clip
    impostor: Impostor | None = None  # set on an impostor LOD (cards showing the atlas's views)


@dataclass(frozen=True, eq=False)
class Asset:
    name: str
    materials: list[Material]
    lods: list[Lod]  # lods[0] is the full-detail tree
    extras: dict = field(default_factory=dict)  # provenance (species, seed, treegen version)
    up_axis: str | None = None  # "y" / "z": the file's up axis where the format has
    # a choice (USD, OBJ); None: the format's default
    # (Y for .usdz and .obj, Z for .usda/.usdc)


@dataclass(frozen=True)
class Instance:
    """One placed tree of a forest: which prototype, where, which LOD, its time offset (s) and
    the phase variant of its prototype's clip that plays closest to that offset."""

    prototype: int
    position: tuple[float, float, float]
    rotation_deg: float  # about +Z
    scale: float
    lod: int = 0
    time_offset: float = 0.0
    distance: float = 0.0  # to the layout's camera, m
    source: str = ""  # JSON path of the layout entry that placed it
    variant: int = 0


@dataclass(eq=False)
class Forest:
    """Prototypes built once and placed many times."""

    name: str
    prototypes: list[Asset]
    instances: list[Instance]
    all_lods: bool = False  # every instance carries every LOD (else its own)
    phase_variants: int = 4
    loop: float = 0.0  # clip period, s (0: static)
    timings: dict = field(default_factory=dict)
    cluster: str = ""  # where the prototypes were built (summary)
    # prepared: per (prototype, LOD) used, the first clip started at each phase variant
    variants: dict[tuple[int, int], list[Clip]] = field(default_factory=dict)
    # prepared: each prototype with its clips played over two periods (room for per-instance
    # time offsets in formats that offset a shared clip, USD)
    looped: list[Asset] = field(default_factory=list)

    def prototype_name(self, p: int) -> str:
        """Prototype `p`'s name in a written forest: its species and seed ("palm_s2")."""
        asset = self.prototypes[p]
        return f"{asset.name}_s{asset.extras.get('seed', p)}"


def lod_bounds(lod: Lod) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) corners of a LOD's rest-pose geometry; zeros when it has none."""
    pts = [np.asarray(p.positions, np.float64) for p in lod.primitives if len(p.positions)]
    if not pts:
        return np.zeros(3), np.zeros(3)
    allp = np.concatenate(pts)
    return allp.min(0), allp.max(0)


def triangle_areas(positions, indices) -> np.ndarray:
    """(T,) float64 areas of the triangles `indices` (flat or (T, 3)) over `positions`."""
    p = np.asarray(positions, np.float64)
    t = np.asarray(indices, np.int64).reshape(-1, 3)
    a = p[t[:, 0]]
    return 0.5 * np.linalg.norm(np.cross(p[t[:, 1]] - a, p[t[:, 2]] - a), axis=1)
