"""UsdSkel reader: a .usda/.usdc/.usdz as a Drawable (LOD k is the k-th SkelRoot), skinned with
UsdSkel's own query, for the preview and the tests.

Materials as the UsdPreviewSurface spec wires them: diffuseColor and opacity constant or from
a UsdUVTexture (its rgb / a outputs; scale multiplies), opacityThreshold > 0 as the cut-out,
normal from a UsdUVTexture (scale 2, bias −1) as a tangent-space map; the texture's st from
the UsdPrimvarReader_float2 its st input connects to (varname followed through material
interface inputs), vertex/varying or faceVarying (then the mesh is split per face corner).
Image files resolve through Ar relative to the layer that authored them, inside a .usdz too
(read out of the package with Sdf.ZipFile). wrapS/T: repeat, clamp, mirror; black previews
as clamp, useMetadata as repeat. Not read: UsdTransform2d, sourceColorSpace "raw" on colour.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..drawable import (
    Drawable,
    Part,
    check_lod,
    decode_image,
    forest_error,
    is_impostor,
    lit_through,
    vertex_normals,
    z_up_to_y_up,
)
from ..errors import TreegenError


def read_drawable(path: Path, lod: int = 0) -> Drawable:
    """A UsdSkel file: LOD k is the k-th SkelRoot; skinning from UsdSkel's own query. A forest's
    trees are instanceable prims (forest_usd.py) that traversal does not enter, so a forest has
    no SkelRoot to read: it is named as a forest."""
    try:
        from pxr import Usd, UsdGeom, UsdShade, UsdSkel
    except ImportError as e:
        raise TreegenError(f"{path}: reading USD needs usd-core ({e})") from None
    try:
        stage = Usd.Stage.Open(str(path))
    except Exception as e:
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise TreegenError(f"{path}: not a readable USD file ({msg[:200]})") from None
    if stage is None:
        raise TreegenError(f"{path}: not a readable USD file")
    to_world = z_up_to_y_up() if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z else np.eye(4)
    skel_roots = [p for p in stage.Traverse() if p.IsA(UsdSkel.Root)]
    if not skel_roots:
        trees = _instanced_trees(stage)
        if trees:
            raise forest_error(path, trees)
        raise TreegenError(f"{path}: no UsdSkel SkelRoot (treegen preview reads skinned trees)")
    check_lod(lod, len(skel_roots), path)
    root = skel_roots[lod]
    cache = UsdSkel.Cache()
    cache.Populate(UsdSkel.Root(root), Usd.PrimDefaultPredicate)
    bindings = cache.ComputeSkelBindings(UsdSkel.Root(root), Usd.PrimDefaultPredicate)
    if not bindings:
        raise TreegenError(f"{path}: SkelRoot {root.GetPath()} binds no meshes to a skeleton")
    binding = bindings[0]
    skel_query = cache.GetSkelQuery(binding.GetSkeleton())
    J = len(skel_query.GetJointOrder())
    tcps = stage.GetTimeCodesPerSecond() or 24.0
    parts = []
    for sq in binding.GetSkinningTargets():
        prim = sq.GetPrim()
        mesh = UsdGeom.Mesh(prim)
        if sq.GetJointMapper() is not None and not sq.GetJointMapper().IsIdentity():
            raise TreegenError(f"{path}: {prim.GetPath()} has its own joint order (not supported)")
        pos = np.asarray(mesh.GetPointsAttr().Get(), dtype=np.float64)
        geom_bind = np.asarray(sq.GetGeomBindTransform(), dtype=np.float64).T
        pos = pos @ geom_bind[:3, :3].T + geom_bind[:3, 3]
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(), dtype=np.int64)
        fvi = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), dtype=np.int64)
        idx = _triangulate(counts, fvi)
        if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
            idx = idx.reshape(-1, 3)[:, ::-1].reshape(-1)
        nrm = mesh.GetNormalsAttr().Get()
        nrm = (
            np.asarray(nrm, np.float64) @ geom_bind[:3, :3].T
            if nrm is not None and len(nrm) == len(pos)
            else vertex_normals(pos, idx)
        )
        ji, jw = sq.ComputeJointInfluences()
        n_inf = sq.GetNumInfluencesPerComponent()
        ji = np.asarray(ji, np.int64).reshape(-1, n_inf)
        jw = np.asarray(jw, np.float32).reshape(-1, n_inf)
        if len(ji) == 1 and len(pos) > 1:  # constant interpolation
            ji, jw = np.repeat(ji, len(pos), 0), np.repeat(jw, len(pos), 0)
        ji, jw = _four_influences(ji, jw)
        color, double = (0.6, 0.6, 0.6), bool(mesh.GetDoubleSidedAttr().Get())
        looks: dict = {}
        material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        material_name = material.GetPrim().GetName() if material else None
        impostor = is_impostor(material_name)
        if material:
            shader = material.ComputeSurfaceSource()[0]
            inp = shader.GetInput("diffuseColor") if shader else None
            if inp and inp.Get() is not None:
                color = tuple(float(c) for c in inp.Get())
            if shader:
                looks = _surface(shader, mesh, path)
                color = looks.pop("color", color)
        uvs = looks.pop("st", None)
        uvs, st_interp = uvs if uvs is not None else (None, None)
        if uvs is not None and st_interp == "faceVarying" and len(uvs) == len(fvi):
            corners = np.arange(len(fvi))
            idx = _triangulate(counts, corners)
            if mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded:
                idx = idx.reshape(-1, 3)[:, ::-1].reshape(-1)
            pos, nrm, ji, jw = pos[fvi], nrm[fvi], ji[fvi], jw[fvi]
        elif uvs is not None and len(uvs) != len(pos):
            uvs = None
        if uvs is None:
            looks = {
                k: v for k, v in looks.items() if k not in ("texture", "normal_map", "wrap", "normal_wrap")
            }
        parts.append(
            Part(
                name=prim.GetName(),
                positions=_apply(to_world, pos).astype(np.float32),
                normals=_apply(to_world, nrm, vector=True).astype(np.float32),
                indices=idx.astype(np.uint32),
                joints=ji,
                weights=jw,
                color=color,
                double_sided=lit_through(material_name, double),
                uvs=uvs,
                impostor=impostor,
                **looks,
            )
        )
    anim = skel_query.GetAnimQuery()
    duration = 0.0
    if anim:
        codes = anim.GetJointTransformTimeSamples()
        if len(codes) > 1:
            duration = (max(codes) - min(codes)) / tcps
    start = stage.GetStartTimeCode() if stage.HasAuthoredTimeCodeRange() else 0.0

    def skinning(t: np.ndarray, _keep=(stage, cache)) -> np.ndarray:  # the query needs both alive
        out = np.empty((len(t), J, 4, 4))
        for i, ti in enumerate(np.atleast_1d(t)):  # frames (tens), not vertices
            xf = skel_query.ComputeSkinningTransforms(Usd.TimeCode(start + float(ti) * tcps))
            out[i] = np.asarray(xf, dtype=np.float64).transpose(0, 2, 1)
        return to_world @ out @ to_world.T

    return Drawable(parts=parts, n_joints=J, duration=duration, skinning=skinning, label=str(path))


USD_WRAP = {
    "repeat": "REPEAT",
    "clamp": "CLAMP",
    "mirror": "MIRROR",
    "black": "CLAMP",
    "useMetadata": "REPEAT",
}


def _instanced_trees(stage) -> int:
    """How many instance prims hold a SkelRoot (a tree) in their prototype; each of the few
    prototypes is searched once."""
    from pxr import Usd, UsdSkel

    has_skel: dict = {}
    n = 0
    for prim in stage.Traverse():  # instances are leaves of this traversal
        if prim.IsInstance():
            proto = prim.GetPrototype()
            key = proto.GetPath()
            if key not in has_skel:
                has_skel[key] = any(p.IsA(UsdSkel.Root) for p in Usd.PrimRange(proto))
            n += has_skel[key]
    return n


def _source(inp):
    """(shader, output name) an input is connected to, or (None, None)."""
    from pxr import UsdShade

    if not inp or not inp.HasConnectedSource():
        return None, None
    src = inp.GetConnectedSources()[0][0]
    return UsdShade.Shader(src.source.GetPrim()), src.sourceName


def _value(shader, name, default=None):
    """An input's value, following connections to material interface inputs."""
    inp = shader.GetInput(name)
    if not inp:
        return default
    attrs = inp.GetValueProducingAttributes()
    v = attrs[0].Get() if attrs else inp.Get()
    return default if v is None else v


def _asset_bytes(asset_path, shader, path) -> bytes:
    """Bytes of a UsdUVTexture file: resolved by Ar against the authoring layer (an asset path
    is relative to the layer that wrote it); package paths (x.usdz[tex/leaf.png]) read out of
    the zip, as Ar's package resolver would."""
    from pxr import Ar, Sdf

    resolved = asset_path.resolvedPath if asset_path is not None else ""
    if not resolved:
        raise TreegenError(
            f"{path}: texture {getattr(asset_path, 'path', '')!r} of "
            f"{shader.GetPath()} not found (resolved against its layer)"
        )
    if Ar.IsPackageRelativePath(resolved):
        outer, inner = Ar.SplitPackageRelativePathOuter(resolved)
        if Ar.IsPackageRelativePath(inner):
            raise TreegenError(f"{path}: texture {resolved!r} in a nested package (not supported)")
        z = Sdf.ZipFile.Open(outer)
        data = z.GetFile(inner) if z else None
        if data is None:
            raise TreegenError(f"{path}: texture {inner!r} missing from package {outer}")
        return bytes(data)
    return Path(resolved).read_bytes()


def _texture(shader, channels: int, path):
    """(image, (wrap s, wrap t), scale, st primvar name) of a UsdUVTexture shader."""
    image = decode_image(
        _asset_bytes(_value(shader, "file"), shader, path), channels, f"{path}: {shader.GetPath()}"
    )
    wrap = tuple(USD_WRAP.get(str(_value(shader, k, "useMetadata")), "REPEAT") for k in ("wrapS", "wrapT"))
    scale = tuple(float(c) for c in _value(shader, "scale", (1.0, 1.0, 1.0, 1.0)))
    reader, _ = _source(shader.GetInput("st"))
    varname = str(_value(reader, "varname", "st")) if reader else "st"
    return image, wrap, scale, varname


def _surface(surf, mesh, path) -> dict:
    """Part fields (and "st", "color") of a UsdPreviewSurface and the mesh's st primvar."""
    from pxr import UsdGeom

    out: dict = {}
    names = []
    tex, _ = _source(surf.GetInput("diffuseColor"))
    if tex is not None and tex.GetIdAttr().Get() == "UsdUVTexture":
        rgba, out["wrap"], scale, name = _texture(tex, 4, path)
        out["texture"], out["color"] = rgba, scale[:3]
        names.append(name)
        op, channel = _source(surf.GetInput("opacity"))
        if op is None:
            rgba[..., 3] = 255  # colour texture, opaque
        elif op.GetPath() != tex.GetPath() or channel != "a":  # alpha from its own texture
            other = _texture(op, 4, path)[0] if op.GetIdAttr().Get() == "UsdUVTexture" else None
            ch = {"r": 0, "g": 1, "b": 2}.get(channel, 3)
            if other is not None and other.shape[:2] == rgba.shape[:2]:
                rgba[..., 3] = other[..., ch]
    else:
        op, _ = _source(surf.GetInput("opacity"))
    if op is None:
        out["opacity"] = float(_value(surf, "opacity", 1.0))
    threshold = float(_value(surf, "opacityThreshold", 0.0))
    if threshold > 0.0:
        out["alpha_cutoff"] = threshold
    ntex, _ = _source(surf.GetInput("normal"))
    if ntex is not None and ntex.GetIdAttr().Get() == "UsdUVTexture":
        nmap, out["normal_wrap"], scale, name = _texture(ntex, 3, path)
        if not names or name == names[0]:
            out["normal_map"], out["normal_scale"] = nmap, abs(scale[0]) / 2.0
            names.append(name)
    if names:
        pv = UsdGeom.PrimvarsAPI(mesh).GetPrimvar(names[0])
        st = pv.ComputeFlattened() if pv and pv.HasValue() else None
        if st is not None and pv.GetInterpolation() in ("vertex", "varying", "faceVarying"):
            out["st"] = (np.asarray(st, np.float32).reshape(-1, 2), str(pv.GetInterpolation()))
    return out


def _apply(m: np.ndarray, v: np.ndarray, vector: bool = False) -> np.ndarray:
    out = np.asarray(v, np.float64) @ m[:3, :3].T
    return out if vector else out + m[:3, 3]


def _triangulate(counts: np.ndarray, fvi: np.ndarray) -> np.ndarray:
    """Fan-triangulate polygons (vectorised over faces of each size)."""
    if len(counts) and np.all(counts == 3):
        return fvi
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tris = []
    for n in np.unique(counts[counts >= 3]):  # one pass per polygon size
        s = starts[counts == n]
        k = np.arange(1, n - 1)
        tris.append(
            np.stack(
                [np.repeat(fvi[s], n - 2), fvi[(s[:, None] + k).ravel()], fvi[(s[:, None] + k + 1).ravel()]],
                axis=1,
            ).ravel()
        )
    return np.concatenate(tris) if tris else np.zeros(0, np.int64)


def _four_influences(ji: np.ndarray, jw: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keep the 4 strongest influences per vertex (renormalised), padding with zero weights."""
    if ji.shape[1] < 4:
        pad = 4 - ji.shape[1]
        return (np.pad(ji, ((0, 0), (0, pad))), np.pad(jw, ((0, 0), (0, pad))))
    if ji.shape[1] > 4:
        top = np.argsort(-jw, axis=1)[:, :4]
        ji, jw = np.take_along_axis(ji, top, 1), np.take_along_axis(jw, top, 1)
        jw = jw / np.maximum(jw.sum(1, keepdims=True), 1e-12)
    return ji, jw
