"""glTF 2.0 writer: Asset → .glb (binary, default) or .gltf + sibling .bin and PNGs.

A lean writer of our own, in parts: `gltf_buffer.py` packs every array into the binary buffer
as accessors, `gltf_mesh.py` encodes the primitives, `gltf_nodes.py` the skeletons and skins,
`gltf_material.py` the materials and their PNGs, `gltf_animation.py` the clips, and
`gltf_container.py` writes the .glb (or .gltf + .bin; a .gltf's textures are PNG files beside
it, `NAME_gltf_leaf.png`, named as texture_files.py names USD's and OBJ's). The JSON is built from plain dicts
and dumped with sorted keys, so the same Asset always gives the same bytes. All core glTF 2.0
(MSFT_lod only as an optional extension; `--compress`: compress.py).

Axes: the generator is Z up, glTF is Y up (right-handed), so every vector goes through
C: (x, y, z) → (x, z, −y); quaternion vector parts likewise; matrices become C·M·Cᵀ.

Node layout: the skinned mesh node of LOD0 and each LOD's rig node (holding that skeleton's
root joint; `skin.skeleton` = the joint) are scene roots, side by side. A mesh node that
parents its own joints hangs Godot 3's importer; a tree node wrapping mesh and joints draws
glTF-Validator's NODE_SKINNED_MESH_NON_ROOT warning; side by side at the root every client
takes them. One rig node per LOD keeps skeletons apart in importers that merge sibling roots
(Godot 3 would make one 444-bone skeleton of four).

    "<name>_LOD0"           mesh + skin, no transform, MSFT_lod → "<name>_LOD1", …
    "<name>_LOD0_rig"       identity
        └── trunk_0 …       LOD0's skeleton (local TRS), joints named by what they are
    "<name>_LOD1_rig"       LOD1's skeleton, …

Lower LODs' mesh nodes are reached only through LOD0's MSFT_lod ids, so clients without
MSFT_lod draw just the full-detail tree; their skeletons stay in the scene so every clip finds
its joints. Each LOD node's extras carry its index, distance and screen coverage.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .. import __version__
from ..asset import Asset
from ..axes import Z_UP_TO_Y_UP
from .compress import GLTF_DEFAULTS, GltfOptions, meshopt_step
from .gltf_animation import animation_dict
from .gltf_buffer import Buffer, finish
from .gltf_container import write_document
from .gltf_material import Textures, material_dict
from .gltf_mesh import primitive_dict, quantization
from .gltf_nodes import inverse_bind_accessor, joint_fields, lod_extras, set_msft_lod
from .impostor_meta import describe, impostor_lod, write_sidecar
from .texture_files import TextureFiles


def build(asset: Asset, options: GltfOptions = GLTF_DEFAULTS) -> tuple[dict, bytes]:
    """Asset → (glTF JSON dict without buffer uri, binary buffer)."""
    gltf, buf = _build(asset, options)
    return gltf, buf.blob()


def _build(
    asset: Asset, options: GltfOptions = GLTF_DEFAULTS, files: TextureFiles | None = None
) -> tuple[dict, Buffer]:
    """Asset → (glTF JSON dict without buffer uri, the unjoined buffer); `files`: the PNGs go
    there (a .gltf's), not into the buffer."""
    buf = Buffer(meshopt=options.compress == "meshopt", pooled=options.quantized)
    textures = Textures(buf, files)
    mat_index = {m.name: i for i, m in enumerate(asset.materials)}
    steps = [
        meshopt_step(options, lod.distance) if options.compress == "meshopt" else 0.0 for lod in asset.lods
    ]
    quants = (
        [quantization(asset, k, steps[k]) for k in range(len(asset.lods))]
        if options.quantized
        else [None] * len(asset.lods)
    )
    uv_boxes = quants[0].uvs if quants and quants[0] is not None else {}
    materials = [material_dict(m, textures, uv_boxes.get(m.name)) for m in asset.materials]

    nodes: list[dict] = []
    meshes, skins, animations, lod_nodes, rig_nodes = [], [], [], [], []
    for k, lod in enumerate(asset.lods):
        sk = lod.skeleton
        J = len(sk.names)
        mesh_node = len(nodes)
        rig_node = mesh_node + 1
        joint_nodes = rig_node + 1 + np.arange(J)
        lod_nodes.append(mesh_node)
        nodes.append({})  # filled below
        parent = np.asarray(sk.parent)
        roots = np.flatnonzero(parent < 0)
        rig_nodes.append(rig_node)
        nodes.append(
            {
                "name": f"{asset.name}_LOD{asset.extras.get('lod_index', k)}_rig",
                "children": [int(x) for x in joint_nodes[roots]],
            }
        )
        for j, fields in enumerate(joint_fields(sk, options.quantized)):
            n = {"name": sk.names[j], **fields}
            kids = np.flatnonzero(parent == j)
            if len(kids):
                n["children"] = [int(x) for x in joint_nodes[kids]]
            nodes.append(n)
        skin = {
            "name": f"{asset.name}_LOD{asset.extras.get('lod_index', k)}_skin",
            "joints": [int(x) for x in joint_nodes],
            "inverseBindMatrices": inverse_bind_accessor(
                buf, sk, quants[k].grid if quants[k] is not None else None
            ),
        }
        if len(roots) == 1:
            skin["skeleton"] = int(joint_nodes[roots[0]])
        skins.append(skin)
        missing = {p.material for p in lod.primitives} - set(mat_index)
        if missing:
            raise ValueError(f"primitives use materials {sorted(missing)} not in asset.materials")
        prims = [primitive_dict(buf, p, J, mat_index[p.material], quants[k]) for p in lod.primitives]
        name = f"{asset.name}_LOD{asset.extras.get('lod_index', k)}"
        meshes.append({"name": name, "primitives": prims})
        nodes[mesh_node] = {
            "name": name,
            "mesh": len(meshes) - 1,
            "skin": len(skins) - 1,
            "extras": lod_extras(asset, k),
        }
        for clip in lod.clips:
            plan = clip.plan if options.quantized else None  # key_plan.with_key_plans
            animations.append(animation_dict(buf, clip, sk, joint_nodes, options.quantized, plan))

    gltf: dict = {
        "asset": {"version": "2.0", "generator": f"treegen {__version__}"},
        "scene": 0,
        # the skinned mesh and each skeleton's rig node are scene roots, side by side (see the
        # module docstring); a lower LOD's mesh is reached only through MSFT_lod, its skeleton
        # is in the scene so its clip always finds its joints
        "scenes": [{"name": asset.name, "nodes": [lod_nodes[0], *rig_nodes]}],
        "nodes": nodes,
        "meshes": meshes,
        "skins": skins,
        "materials": materials,
    }
    k = impostor_lod(asset)
    extras = dict(asset.extras)
    if k is not None:
        imp = asset.lods[k].impostor
        extras["treegen_impostor"] = describe(
            asset,
            k,
            Z_UP_TO_Y_UP,
            {"albedo": textures.image(imp.albedo), "normal_depth": textures.image(imp.normal_depth)},
        )
    textures.fields(gltf)
    if extras:
        gltf["asset"]["extras"] = extras
    if animations:
        gltf["animations"] = animations
    if len(asset.lods) > 1:
        set_msft_lod(nodes[lod_nodes[0]], lod_nodes[1:], asset.lods)
        gltf["extensionsUsed"] = ["MSFT_lod"]
    return gltf, finish(gltf, buf, options.quantized, uv_boxes.values())


def write_gltf(
    asset: Asset,
    path: str | os.PathLike,
    binary: bool | None = None,
    options: GltfOptions = GLTF_DEFAULTS,
    textures: TextureFiles | None = None,
) -> None:
    """Write straight to `path` (and `<stem>.bin` and the PNGs beside a .gltf; `textures`: their
    names, shared by `--lod-files` parts); not atomic on its own — `exchange.export` stages it."""
    path = Path(path)
    if binary is None:
        binary = path.suffix.lower() != ".gltf"
    files = None if binary else textures or TextureFiles(path)
    gltf, buf = _build(asset, options, files)
    write_document(gltf, buf, path, binary, files.files if files is not None else {})
    meta = gltf["asset"].get("extras", {}).get("treegen_impostor")
    if meta is not None:  # for engines' impostor shaders: images are in the file
        write_sidecar(meta | {"file": path.name}, path)
