"""UsdSkel reader: a .usda/.usdc/.usdz as a Drawable (LOD k is the k-th SkelRoot), skinned with
UsdSkel's own query, for the preview and the tests."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..drawable import Drawable, Part, check_lod, vertex_normals, z_up_to_y_up
from ..errors import TreegenError


def read_drawable(path: Path, lod: int = 0) -> Drawable:
    """A UsdSkel file: LOD k is the k-th SkelRoot; skinning from UsdSkel's own query."""
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
        nrm = (np.asarray(nrm, np.float64) @ geom_bind[:3, :3].T if nrm is not None and len(nrm) == len(pos)
               else vertex_normals(pos, idx))
        ji, jw = sq.ComputeJointInfluences()
        n_inf = sq.GetNumInfluencesPerComponent()
        ji = np.asarray(ji, np.int64).reshape(-1, n_inf)
        jw = np.asarray(jw, np.float32).reshape(-1, n_inf)
        if len(ji) == 1 and len(pos) > 1:                          # constant interpolation
            ji, jw = np.repeat(ji, len(pos), 0), np.repeat(jw, len(pos), 0)
        ji, jw = _four_influences(ji, jw)
        color, double = (0.6, 0.6, 0.6), bool(mesh.GetDoubleSidedAttr().Get())
        material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        if material:
            shader = material.ComputeSurfaceSource()[0]
            inp = shader.GetInput("diffuseColor") if shader else None
            if inp and inp.Get() is not None:
                color = tuple(float(c) for c in inp.Get())
        parts.append(Part(name=prim.GetName(), positions=_apply(to_world, pos).astype(np.float32),
                          normals=_apply(to_world, nrm, vector=True).astype(np.float32),
                          indices=idx.astype(np.uint32), joints=ji, weights=jw, color=color,
                          double_sided=double))
    anim = skel_query.GetAnimQuery()
    duration = 0.0
    if anim:
        codes = anim.GetJointTransformTimeSamples()
        if len(codes) > 1:
            duration = (max(codes) - min(codes)) / tcps
    start = stage.GetStartTimeCode() if stage.HasAuthoredTimeCodeRange() else 0.0

    def skinning(t: np.ndarray, _keep=(stage, cache)) -> np.ndarray:   # the query needs both alive
        out = np.empty((len(t), J, 4, 4))
        for i, ti in enumerate(np.atleast_1d(t)):     # frames (tens), not vertices
            xf = skel_query.ComputeSkinningTransforms(Usd.TimeCode(start + float(ti) * tcps))
            out[i] = np.asarray(xf, dtype=np.float64).transpose(0, 2, 1)
        return to_world @ out @ to_world.T

    return Drawable(parts=parts, n_joints=J, duration=duration, skinning=skinning, label=str(path))


def _apply(m: np.ndarray, v: np.ndarray, vector: bool = False) -> np.ndarray:
    out = np.asarray(v, np.float64) @ m[:3, :3].T
    return out if vector else out + m[:3, 3]


def _triangulate(counts: np.ndarray, fvi: np.ndarray) -> np.ndarray:
    """Fan-triangulate polygons (vectorised over faces of each size)."""
    if len(counts) and np.all(counts == 3):
        return fvi
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    tris = []
    for n in np.unique(counts[counts >= 3]):          # one pass per polygon size
        s = starts[counts == n]
        k = np.arange(1, n - 1)
        tris.append(np.stack([np.repeat(fvi[s], n - 2), fvi[(s[:, None] + k).ravel()],
                              fvi[(s[:, None] + k + 1).ravel()]], axis=1).ravel())
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


