"""glTF reader: a .glb/.gltf (ours, or any triangle glTF with at most one skin per LOD node) as a
Drawable, for the preview and the tests. LOD k is the k-th node of the first mesh node's
MSFT_lod chain; animation samplers are played with glTF's own interpolation rules.
"""
from __future__ import annotations

import struct
from pathlib import Path

import numpy as np

from ..drawable import Channel, Drawable, Part, PoseRig, check_lod, vertex_normals
from ..errors import TreegenError
from ..skeleton import forward, trs
from .gltf import read_accessor, read_gltf


def _node_world(gltf: dict) -> tuple[np.ndarray, np.ndarray]:
    """(parent per node, rest world matrix per node) from the node hierarchy."""
    nodes = gltf.get("nodes", [])
    n = len(nodes)
    parent = np.full(n, -1, dtype=np.int64)
    for i, node in enumerate(nodes):              # JSON nodes: one Python step each
        for c in node.get("children", []):
            parent[c] = i
    local = np.empty((n, 4, 4))
    for i, node in enumerate(nodes):
        if "matrix" in node:
            local[i] = np.asarray(node["matrix"], dtype=np.float64).reshape(4, 4).T
        else:
            local[i] = trs(np.asarray(node.get("translation", [0, 0, 0]), float),
                           np.asarray(node.get("rotation", [0, 0, 0, 1]), float),
                           np.asarray(node.get("scale", [1, 1, 1]), float))
    return parent, forward(parent, local)


def read_drawable(path: Path, lod: int = 0) -> Drawable:
    """A .glb/.gltf (ours, or any triangle glTF with at most one skin per LOD node)."""
    try:
        gltf, blob = read_gltf(path)
        return _gltf_scene(gltf, blob, read_accessor, lod, path)
    except TreegenError:
        raise
    except (OSError, ValueError, KeyError, IndexError, TypeError, struct.error) as e:
        raise TreegenError(f"{path}: not a readable glTF file ({type(e).__name__}: {e})") from None


def _gltf_scene(gltf, blob, read_accessor, lod, path) -> Drawable:
    nodes = gltf.get("nodes", [])
    scene = gltf.get("scenes", [{}])[gltf.get("scene", 0)]
    roots = [i for i in scene.get("nodes", []) if "mesh" in nodes[i]] or \
            [i for i, nd in enumerate(nodes) if "mesh" in nd][:1]
    if not roots:
        raise TreegenError(f"{path}: no mesh in the glTF scene")
    lod_nodes = [roots[0]] + list(nodes[roots[0]].get("extensions", {}).get("MSFT_lod", {}).get("ids", []))
    check_lod(lod, len(lod_nodes), path)
    node_index = lod_nodes[lod]
    node = nodes[node_index]
    parent, world = _node_world(gltf)
    materials = gltf.get("materials", [])

    skin = gltf["skins"][node["skin"]] if "skin" in node else None
    if skin is not None:
        joints = np.asarray(skin["joints"], dtype=np.int64)
        J = len(joints)
        ibm = (read_accessor(gltf, blob, skin["inverseBindMatrices"]).astype(np.float64)
               if "inverseBindMatrices" in skin else np.broadcast_to(np.eye(4), (J, 4, 4)))
    else:
        joints, J = np.array([node_index]), 1      # static: S = world of the mesh node
        ibm = np.eye(4)[None]

    parts = []
    for k, prim in enumerate(gltf["meshes"][node["mesh"]]["primitives"]):
        if prim.get("mode", 4) != 4:
            continue
        a = prim["attributes"]
        pos = read_accessor(gltf, blob, a["POSITION"]).astype(np.float32)
        idx = (read_accessor(gltf, blob, prim["indices"]).astype(np.uint32) if "indices" in prim
               else np.arange(len(pos), dtype=np.uint32))
        nrm = (read_accessor(gltf, blob, a["NORMAL"]).astype(np.float32) if "NORMAL" in a
               else vertex_normals(pos, idx))
        if skin is not None and "JOINTS_0" in a:
            jnt = read_accessor(gltf, blob, a["JOINTS_0"]).astype(np.int64)
            wgt = read_accessor(gltf, blob, a["WEIGHTS_0"]).astype(np.float32)
        else:
            jnt = np.zeros((len(pos), 4), np.int64)
            wgt = np.tile(np.float32([1, 0, 0, 0]), (len(pos), 1))
        mat = materials[prim["material"]] if "material" in prim else {}
        color = mat.get("pbrMetallicRoughness", {}).get("baseColorFactor", [0.6, 0.6, 0.6, 1])
        parts.append(Part(name=mat.get("name", f"primitive{k}"), positions=pos, normals=nrm,
                          indices=idx, joints=jnt, weights=wgt, color=tuple(color[:3]),
                          double_sided=bool(mat.get("doubleSided", False))))

    jparent = np.full(J, -1, dtype=np.int64)
    slot = {int(n): j for j, n in enumerate(joints)}
    for j, n in enumerate(joints):                # joints: hundreds at most
        jparent[j] = slot.get(int(parent[n]), -1)
    above = parent[joints]
    root_world = np.broadcast_to(np.eye(4), (J, 4, 4)).copy()
    outside = (jparent < 0) & (above >= 0)           # a root joint under a non-joint node
    root_world[outside] = world[above[outside]]
    rest = [nodes[n] for n in joints]
    rig = PoseRig(
        parent=jparent,
        translation=np.array([n.get("translation", [0, 0, 0]) for n in rest], float).reshape(J, 3),
        rotation=np.array([n.get("rotation", [0, 0, 0, 1]) for n in rest], float).reshape(J, 4),
        scale=np.array([n.get("scale", [1, 1, 1]) for n in rest], float).reshape(J, 3),
        root_world=root_world, inverse_bind=ibm,
        channels=_gltf_channels(gltf, blob, read_accessor, slot) if skin is not None else [])
    if any("matrix" in n for n in rest):
        raise TreegenError(f"{path}: joint nodes with 'matrix' transforms are not supported")
    return Drawable(parts=parts, n_joints=J, duration=rig.duration,
                 skinning=rig.skinning, label=str(path))


def _gltf_channels(gltf, blob, read_accessor, slot: dict[int, int]) -> list[Channel]:
    """Channels of the first animation that moves any of this skin's joints."""
    for anim in gltf.get("animations", []):
        out = []
        for ch in anim["channels"]:            # one per animated joint (hundreds)
            node, path = ch["target"].get("node"), ch["target"]["path"]
            if node not in slot or path not in ("rotation", "translation", "scale"):
                continue
            s = anim["samplers"][ch["sampler"]]
            times = read_accessor(gltf, blob, s["input"]).astype(np.float64)
            values = read_accessor(gltf, blob, s["output"]).astype(np.float64)
            out.append(Channel(np.array([slot[node]]), path, times, values[:, None, :],
                               s.get("interpolation", "LINEAR")))
        if out:
            return out
    return []
