"""Forest → one glTF 2.0 file whose binary grows with prototypes, not with trees.

Shared, written once per (prototype, LOD): the mesh (all vertex data), the skin's inverse bind
matrices accessor, and per phase variant the animation sampler data (input times and output
rotations). Per instance (JSON only): its own joint node hierarchy and its own skin object
(a node has one parent, so joints cannot be shared), and one channel per animated joint
pointing at the shared sampler of its variant.

Per instance and LOD k, two scene roots side by side (a skinned mesh must not parent its own
joints: Godot 3 hangs on that, and the validator wants skinned meshes at the root):

    "<tree>_LOD<k>"          mesh + skin, no transform
    "<tree>_LOD<k>_place"    instance TRS (Y up)
        └── joints           the prototype's skeleton (local TRS), named as in the prototype,
                             so importers that merge identical skins (Godot) find every bone

One animation "wind_loop" drives every instance (engines that loop clips by name do); phase
variety comes from `phase_variants` copies of each clip, key arrays rotated (Forest.variants,
prepared), each instance playing the variant the forest stage chose for its time offset. With
`all_lods` every LOD of every instance is written and LOD0's node lists the others with
MSFT_lod (lower LODs' meshes are reached only through it).

`--compress quantize|meshopt` (compress.py) encodes the shared data as the tree writer does:
one position grid per (prototype, LOD) skin, folded into its inverse bind matrices, one UV box
per material over every prototype using it, int16 rotation keys; meshopt then encodes every
view. Per-instance JSON is unchanged, so the saving grows with prototypes, not trees.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .. import __version__
from ..asset import Forest, Material
from .compress import GLTF_DEFAULTS, GltfOptions, UvRange, meshopt_step, position_grid, uv_range
from ..axes import to_y_up
from .gltf_animation import rotation_samplers, tracked_joints
from .gltf_buffer import Buffer, finish
from .gltf_container import write_document
from .gltf_material import Textures, material_dict
from .gltf_mesh import Quantization, gltf_uvs, primitive_dict, y_up32
from .gltf_nodes import inverse_bind_accessor, is_default, joint_fields, lod_extras, set_msft_lod
from .texture_files import TextureFiles


class _Shared:
    """Lazily written per-(prototype, LOD[, variant]) data, so unused LODs cost nothing."""

    def __init__(
        self,
        scene: Forest,
        buf: Buffer,
        options: GltfOptions = GLTF_DEFAULTS,
        files: TextureFiles | None = None,
    ):
        self.scene, self.buf, self.options = scene, buf, options
        self.uv_boxes = _uv_boxes(scene) if options.quantized else {}
        self._quant: dict = {}
        self.textures = Textures(buf, files)
        self.materials: list[dict] = []
        self._mat: dict = {}
        self.meshes: list[dict] = []
        self._mesh: dict = {}
        self._ibm: dict = {}
        self._joints: dict = {}
        self._inputs: dict = {}
        self._tracks: dict = {}
        self.samplers: list[dict] = []

    def material(self, m, owner: str) -> int:
        """The shared material `m`, named after its first prototype (`owner`, e.g.
        "black_tupelo_s7"): every species has a "bark", "leaf" and "impostor", and engines
        that key materials by name (Blender's .001 copies) would mix them up."""
        if m not in self._mat:
            self._mat[m] = len(self.materials)
            d = material_dict(m, self.textures, self.uv_boxes.get(m), f"{owner}_")
            self.materials.append({**d, "name": f"{owner}_{d['name']}"})
        return self._mat[m]

    def quant(self, p: int, k: int) -> Quantization | None:
        """--compress: LOD k of prototype p's position grid (meshopt: coarsened to a quarter
        pixel at the LOD's distance) and its materials' UV boxes; None uncompressed."""
        if not self.options.quantized:
            return None
        if (p, k) not in self._quant:
            asset = self.scene.prototypes[p]
            lod = asset.lods[k]
            step = meshopt_step(self.options, lod.distance) if self.options.compress == "meshopt" else 0.0
            grid = position_grid([y_up32(q.positions) for q in lod.primitives], step)
            self._quant[(p, k)] = Quantization(
                grid, {m.name: self.uv_boxes[m] for m in asset.materials if m in self.uv_boxes}
            )
        return self._quant[(p, k)]

    def mesh(self, p: int, k: int) -> int:
        if (p, k) not in self._mesh:
            asset = self.scene.prototypes[p]
            lod = asset.lods[k]
            mats = {m.name: m for m in asset.materials}
            J = len(lod.skeleton.names)
            quant = self.quant(p, k)
            owner = self.scene.prototype_name(p)
            prims = [
                primitive_dict(self.buf, q, J, self.material(mats[q.material], owner), quant)
                for q in lod.primitives
            ]
            self._mesh[(p, k)] = len(self.meshes)
            self.meshes.append({"name": f"{owner}_LOD{k}", "primitives": prims})
        return self._mesh[(p, k)]

    def ibm(self, p: int, k: int) -> int:
        if (p, k) not in self._ibm:
            quant = self.quant(p, k)
            self._ibm[(p, k)] = inverse_bind_accessor(
                self.buf, self.scene.prototypes[p].lods[k].skeleton, quant.grid if quant is not None else None
            )
        return self._ibm[(p, k)]

    def joints(self, p: int, k: int) -> tuple[list[dict], list[list[int]]]:
        """Per joint of LOD k: its node's rest TRS fields and its children (joint indices);
        the same for every tree of the prototype, so computed once."""
        if (p, k) not in self._joints:
            sk = self.scene.prototypes[p].lods[k].skeleton
            parent = np.asarray(sk.parent)
            kids: list[list[int]] = [[] for _ in range(len(parent))]
            for j in np.flatnonzero(parent >= 0):
                kids[parent[j]].append(int(j))
            self._joints[(p, k)] = (joint_fields(sk, self.options.quantized), kids)
        return self._joints[(p, k)]

    def tracks(self, p: int, k: int, v: int) -> list[tuple[int, int]]:
        """[(joint, sampler index)] of variant v of LOD k's first clip (empty if static)."""
        key = (p, k, v)
        if key in self._tracks:
            return self._tracks[key]
        out: list[tuple[int, int]] = []
        if (p, k) in self.scene.variants:
            clip = self.scene.variants[(p, k)][v]
            joints = tracked_joints(clip)  # (a still clip: the root's, as in a single tree)
            for j, sampler in rotation_samplers(self.buf, clip, joints, self._inputs, self.options.quantized):
                self.samplers.append(sampler)
                out.append((j, len(self.samplers) - 1))
        self._tracks[key] = out
        return out


def _uv_boxes(scene: Forest) -> dict[Material, UvRange]:
    """Each material's UV box over every prototype and LOD that uses it (--compress)."""
    by: dict[Material, list[np.ndarray]] = {}
    for asset in scene.prototypes:
        mats = {m.name: m for m in asset.materials}
        for lod in asset.lods:
            for q in lod.primitives:
                by.setdefault(mats[q.material], []).append(gltf_uvs(q))
    return {m: uv_range(u) for m, u in by.items()}


def build_forest(scene: Forest, options: GltfOptions = GLTF_DEFAULTS) -> tuple[dict, bytes]:
    """Scene → (glTF JSON dict without buffer uri, binary buffer)."""
    gltf, buf = _build_forest(scene, options)
    return gltf, buf.blob()


def _build_forest(
    scene: Forest, options: GltfOptions = GLTF_DEFAULTS, files: TextureFiles | None = None
) -> tuple[dict, Buffer]:
    """Scene → (glTF JSON dict without buffer uri, the unjoined buffer); `files`: the PNGs
    go there (a .gltf's: `NAME_gltf_<prototype>_leaf.png`), not into the buffer."""
    buf = Buffer(meshopt=options.compress == "meshopt", pooled=options.quantized)
    sh = _Shared(scene, buf, options, files)
    nodes: list[dict] = []
    skins: list[dict] = []
    channels: list[dict] = []
    roots: list[int] = []
    places: list[int] = []
    width = len(str(max(len(scene.instances) - 1, 0)))
    for i, inst in enumerate(scene.instances):  # per tree: JSON records only, no vertex data
        asset = scene.prototypes[inst.prototype]
        name = f"tree{i:0{width}d}"
        t = to_y_up(np.asarray(inst.position, np.float64))
        half = math.radians(inst.rotation_deg) / 2
        q = np.array([0.0, math.sin(half), 0.0, math.cos(half)])  # about glTF's up (+Y)
        lods = range(len(asset.lods)) if scene.all_lods else [inst.lod]
        lod_nodes = []
        for k in lods:
            sk = asset.lods[k].skeleton
            J = len(sk.names)
            mesh_node = len(nodes)
            place = mesh_node + 1
            joint_nodes = place + 1 + np.arange(J)
            parent = np.asarray(sk.parent)
            jroots = np.flatnonzero(parent < 0)
            place_node = {"name": f"{name}_LOD{k}_place", "children": [int(x) for x in joint_nodes[jroots]]}
            if not is_default(t, [0, 0, 0]):
                place_node["translation"] = [float(x) for x in t]
            if inst.rotation_deg % 360 != 0:
                place_node["rotation"] = [float(x) for x in q]
            if inst.scale != 1.0:
                place_node["scale"] = [float(inst.scale)] * 3
            nodes.append(
                {
                    "name": f"{name}_LOD{k}",
                    "mesh": sh.mesh(inst.prototype, k),
                    "skin": len(skins),
                    "extras": lod_extras(asset, k, inst.scale),
                }
            )
            nodes.append(place_node)
            fields, kids = sh.joints(inst.prototype, k)
            first = int(joint_nodes[0]) if J else 0
            for j in range(J):  # one JSON node per joint, fields shared with the prototype
                n = {"name": sk.names[j], **fields[j]}  # same names in every instance:
                if kids[j]:  # importers merge identical skins
                    n["children"] = [first + c for c in kids[j]]
                nodes.append(n)
            skin = {
                "name": f"{name}_LOD{k}_skin",
                "joints": [int(x) for x in joint_nodes],
                "inverseBindMatrices": sh.ibm(inst.prototype, k),
            }
            if len(jroots) == 1:
                skin["skeleton"] = int(joint_nodes[jroots[0]])
            skins.append(skin)
            for j, sampler in sh.tracks(inst.prototype, k, inst.variant):
                channels.append(
                    {"sampler": sampler, "target": {"node": int(joint_nodes[j]), "path": "rotation"}}
                )
            lod_nodes.append(mesh_node)
            places.append(place)
        if len(lod_nodes) > 1:
            set_msft_lod(nodes[lod_nodes[0]], lod_nodes[1:], asset.lods)
        roots.append(lod_nodes[0])

    gltf: dict = {
        "asset": {
            "version": "2.0",
            "generator": f"treegen {__version__}",
            "extras": {
                "forest": scene.name,
                "instances": len(scene.instances),
                "prototypes": [dict(a.extras) for a in scene.prototypes],
            },
        },
        "scene": 0,
        "scenes": [{"name": scene.name, "nodes": roots + places}],
        "nodes": nodes,
        "meshes": sh.meshes,
        "skins": skins,
        "materials": sh.materials,
    }
    sh.textures.fields(gltf)
    if channels:
        gltf["animations"] = [{"name": "wind_loop", "samplers": sh.samplers, "channels": channels}]
    if any("extensions" in n for n in nodes):
        gltf["extensionsUsed"] = ["MSFT_lod"]
    return gltf, finish(gltf, buf, options.quantized, sh.uv_boxes.values())


def write_forest_gltf(scene: Forest, path: str | os.PathLike, options: GltfOptions = GLTF_DEFAULTS) -> None:
    """Write straight to `path` (.glb, or .gltf + `<stem>.bin` and its PNGs);
    exchange.export_forest stages it."""
    path = Path(path)
    binary = path.suffix.lower() != ".gltf"
    files = None if binary else TextureFiles(path)
    gltf, buf = _build_forest(scene, options, files)
    write_document(gltf, buf, path, binary, files.files if files is not None else {})
