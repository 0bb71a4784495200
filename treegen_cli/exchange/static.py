"""Asset → .obj (+ .mtl and textures) / .ply: the rest pose of one LOD, no skin or animation.

OBJ is written here as text (trimesh's exporter names and re-encodes textures itself): one
vertex list, then one group per primitive (`g bark` / `g leaves`) with its own material
(`usemtl bark` / `usemtl leaf`), `v/vt/vn` on every corner. UVs are the Asset's (origin
bottom-left, OBJ's convention too). `<stem>.mtl` beside it holds the materials: Kd from
base_color, `map_Kd` the base texture, `map_d` the same RGBA image for cut-out leaves (its
alpha), `map_Bump -bm 1` the tangent-space normal map (Blender's reading of map_Bump);
textures are flat siblings `<stem>_obj_<name>.png` (texture_files.py: the extension keeps
them apart from the textures of an `<stem>.usdc` in the same folder).

PLY goes through trimesh: positions and normals only.

Up axis: Y by default (OBJ/PLY consumers mostly assume Y up), "z" keeps generator space;
metres either way.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..asset import Asset, Material
from ..axes import to_y_up
from ..errors import TreegenError
from .texture_files import TextureFiles


def write_static(asset: Asset, path: Path, lod: int = 0) -> None:
    """Rest-pose geometry of LOD `lod`: .obj with groups, materials and textures; .ply as one
    mesh."""
    path = Path(path)
    up = (asset.up_axis or "y").lower()
    if up not in ("y", "z"):
        raise TreegenError(f"up axis {asset.up_axis!r}: expected y or z")
    axes = to_y_up if up == "y" else np.asarray
    prims = asset.lods[lod].primitives
    if path.suffix.lower() == ".obj":
        _write_obj(asset, prims, path, axes)
        return
    import trimesh  # lazy: trimesh is slow to import and only PLY needs it

    counts = np.array([len(p.positions) for p in prims])
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    vertices = axes(np.concatenate([np.asarray(p.positions, np.float64) for p in prims]))
    normals = axes(np.concatenate([np.asarray(p.normals, np.float64) for p in prims]))
    faces = np.concatenate(
        [np.asarray(p.indices, np.int64).reshape(-1, 3) + o for p, o in zip(prims, offsets)]
    )
    mesh = trimesh.Trimesh(vertices=vertices, faces=faces, vertex_normals=normals, process=False)
    mesh.export(path)


def _rows(fmt: str, values: np.ndarray) -> str:
    """One formatted line per row (C-level formatting of the whole block at once)."""
    values = np.asarray(values)
    if not len(values):
        return ""
    return (fmt * len(values)) % tuple(values.ravel().tolist())


def _write_obj(asset: Asset, prims, path: Path, axes) -> None:
    textures = TextureFiles(path, packaged=False)
    mtl_name = path.stem + ".mtl"
    used = [p.material for p in prims if len(p.indices)]
    materials = [m for m in asset.materials if m.name in used]
    lines = [
        f"# treegen: {asset.name}, rest pose, metres\n",
        f"mtllib {mtl_name}\n",
        f"o {_token(asset.name)}\n",
    ]
    pos = [axes(np.asarray(p.positions, np.float64)) for p in prims]
    nrm = [axes(np.asarray(p.normals, np.float64)) for p in prims]
    lines += [_rows("v %.6f %.6f %.6f\n", p) for p in pos]
    lines += [_rows("vt %.6f %.6f\n", np.asarray(p.uvs, np.float64)) for p in prims]
    lines += [_rows("vn %.6f %.6f %.6f\n", n) for n in nrm]
    base = 1
    for p in prims:
        idx = np.asarray(p.indices, np.int64).reshape(-1, 3) + base
        base += len(p.positions)
        if not len(idx):
            continue
        lines.append(f"g {_token(p.name)}\nusemtl {_token(p.material)}\n")
        lines.append(_rows("f %d/%d/%d %d/%d/%d %d/%d/%d\n", np.repeat(idx, 3, axis=1)))
    mtl = ["# treegen materials\n"] + [_mtl(m, textures) for m in materials]
    path.write_text("".join(lines))
    (path.parent / mtl_name).write_text("".join(mtl))
    for name, data in sorted(textures.files.items()):
        (path.parent / name).write_bytes(data)


def _mtl(m: Material, textures: TextureFiles) -> str:
    r, g, b, a = (float(c) for c in m.base_color)
    shininess = (1.0 - float(m.roughness)) ** 2 * 1000.0  # Blender's roughness ↔ Ns mapping
    out = [
        f"\nnewmtl {_token(m.name)}\n",
        f"Kd {r:.6f} {g:.6f} {b:.6f}\n",
        "Ks 0.000000 0.000000 0.000000\n",
        f"Ns {shininess:.6f}\n",
        f"d {a:.6f}\n",
        "illum 2\n",
    ]
    if m.base_texture is not None:
        name = textures.name(m.base_texture)
        out.append(f"map_Kd {name}\n")
        if m.alpha_cutoff is not None:
            out.append(f"map_d {name}\n")
    if m.normal_texture is not None:
        out.append(f"map_Bump -bm 1.000000 {textures.name(m.normal_texture)}\n")
    return "".join(out)


def _token(name: str) -> str:
    """OBJ/MTL names are whitespace-separated tokens."""
    return "_".join(str(name).split()) or "unnamed"
