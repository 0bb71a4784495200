"""UsdSkel: one LOD as a SkelRoot holding its Skeleton, SkelAnimation(s) and skinned meshes.
USD matrices are row-vector (p' = p·M): every matrix here is the transpose of the Asset's."""

from __future__ import annotations

import numpy as np

from ..asset import Asset, Clip, Lod, Material, Primitive, Skeleton
from ..errors import TreegenError
from ..quat import continuous, to_matrix
from .usd_stage import Axes, gf_vec3f, identifier, snap, unique


def define_skel_root(stage, path, lod: Lod, asset: Asset, materials, tcps, axes: Axes) -> None:
    """One SkelRoot: Skeleton, its SkelAnimation(s), and the skinned meshes."""
    from pxr import UsdSkel

    skel_root = UsdSkel.Root.Define(stage, path)
    if lod.bounds is None:
        raise ValueError(f"asset {asset.name!r}: not prepared (prepare.prepare before export)")
    lo, hi = axes.box(*lod.bounds)
    skel_root.CreateExtentAttr([gf_vec3f(lo), gf_vec3f(hi)])
    skel_path = path.AppendChild("Skeleton")
    joint_paths = _define_skeleton(stage, skel_path, lod.skeleton, axes)

    anim_paths = []
    used = {"Skeleton"}
    for clip in lod.clips:
        name = unique(identifier(clip.name), used)
        anim_paths.append(path.AppendChild(name))
        _define_animation(stage, anim_paths[-1], clip, lod.skeleton, joint_paths, tcps, axes)
    if anim_paths:
        binding = UsdSkel.BindingAPI.Apply(stage.GetPrimAtPath(skel_path))
        binding.CreateAnimationSourceRel().SetTargets([anim_paths[0]])

    for prim in lod.primitives:
        name = unique(identifier(prim.name), used)
        mat = next((m for m in asset.materials if m.name == prim.material), None)
        _define_mesh(
            stage,
            path.AppendChild(name),
            prim,
            skel_path,
            materials.get(prim.material),
            mat,
            len(lod.skeleton.names),
            axes,
        )


def _define_skeleton(stage, path, skel: Skeleton, axes: Axes) -> list[str]:
    """Joints as path tokens "j0", "j0/j1", ...; bind = world, rest = local (row-vector)."""
    from pxr import UsdSkel, Vt

    joint_paths = _joint_paths(skel)
    s = UsdSkel.Skeleton.Define(stage, path)
    s.CreateJointsAttr(Vt.TokenArray(joint_paths))
    s.CreateJointNamesAttr(Vt.TokenArray(list(skel.names)))
    bind = axes.matrices(np.asarray(skel.bind_world, np.float64))
    bind = np.ascontiguousarray(np.transpose(bind, (0, 2, 1)))
    s.CreateBindTransformsAttr(Vt.Matrix4dArray.FromNumpy(bind))
    rest = axes.matrices(_rest_matrices(skel))
    s.CreateRestTransformsAttr(
        Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(np.transpose(rest, (0, 2, 1))))
    )
    return joint_paths


def _define_animation(stage, path, clip: Clip, skel: Skeleton, joint_paths, tcps, axes: Axes) -> None:
    """SkelAnimation for the joints that move: rotations time-sampled, translations and scales
    at rest (default value only).

    USD samples every joint of an animation at the same time codes, while Clip.keys keeps keys
    per joint: Clip.timeline (prepare.py, clip.union_timeline) holds the union of the kept keys
    of the moving joints, each joint playing its own track there (slerp between its kept keys
    for LINEAR, its previous kept key for STEP). USD interpolates quatf samples by slerp, so
    LINEAR playback is reproduced exactly.

    STEP: USD's held interpolation is a per-stage runtime setting, not stored in files. We keep
    linear files and encode the hold by also writing, one frame before each change, the held
    value; playback is then exact at every frame time code (only the last sub-frame ramps).
    customData["treegen:interpolation"] records "STEP" so a player can switch the stage to
    Usd.InterpolationTypeHeld.
    """
    from pxr import UsdSkel, Vt

    if clip.timeline is None or clip.animated is None:
        raise ValueError(f"clip {clip.name!r} is not prepared (prepare.prepare before export)")
    moving = np.flatnonzero(clip.animated)  # the timeline's tracks (the root's, if still)
    frames, rot = clip.timeline
    rot = continuous(axes.quats(rot))  # consecutive samples on one hemisphere: lerping importers are safe
    anim = UsdSkel.Animation.Define(stage, path)
    anim.CreateJointsAttr(Vt.TokenArray([joint_paths[j] for j in moving]))
    anim.CreateTranslationsAttr(
        Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(axes.points(skel.rest_translation[moving]), np.float32))
    )
    anim.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((len(moving), 3), np.float16)))
    rot_attr = anim.CreateRotationsAttr()
    codes = snap(np.asarray(clip.times, np.float64)[frames] * (tcps or 1.0))
    # Vt.QuatfArray.FromNumpy takes rows in GfQuatf memory order (x, y, z, w): the Asset's order
    for code, q in zip(codes, rot):
        rot_attr.Set(Vt.QuatfArray.FromNumpy(np.ascontiguousarray(q, np.float32)), float(code))
    anim.GetPrim().SetCustomDataByKey("treegen:interpolation", clip.interpolation)


def _define_mesh(
    stage, path, prim: Primitive, skel_path, material, mat: Material | None, n_joints: int, axes: Axes
) -> None:
    """Triangle mesh with vertex normals, st, skinning primvars and a material binding."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade, UsdSkel, Vt

    pos = np.ascontiguousarray(axes.points(prim.positions), np.float32)
    idx = np.asarray(prim.indices, np.int64)
    if idx.size % 3 or (idx.size and (idx.min() < 0 or idx.max() >= len(pos))):
        raise TreegenError(f"primitive {prim.name!r}: indices are not a valid triangle list")
    joints = np.asarray(prim.joints, np.int64)
    if joints.size and joints.max() >= n_joints:
        raise TreegenError(f"primitive {prim.name!r}: joint index beyond the skeleton")

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)  # Asset winding: CCW = front
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pos))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(idx.size // 3, 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(idx.astype(np.int32)))
    mesh.CreateNormalsAttr(
        Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(axes.points(prim.normals), np.float32))
    )
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    if len(pos):
        mesh.CreateExtentAttr([Gf.Vec3f(*map(float, pos.min(0))), Gf.Vec3f(*map(float, pos.max(0)))])
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(
        "st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex
    )
    st.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(prim.uvs, np.float32)))
    mesh.CreateDoubleSidedAttr(bool(mat.double_sided) if mat else False)

    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets([skel_path])
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    influences = joints.shape[1] if joints.ndim == 2 else 4
    ji = binding.CreateJointIndicesPrimvar(False, influences)
    ji.Set(Vt.IntArray.FromNumpy(joints.astype(np.int32).reshape(-1)))
    jw = binding.CreateJointWeightsPrimvar(False, influences)
    jw.Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(prim.weights, np.float32).reshape(-1)))

    if material is not None:
        UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(material)


def _joint_paths(skel: Skeleton) -> list[str]:
    """Path tokens from Skeleton.parent (parents come before children)."""
    from pxr import Sdf

    paths: list[str] = []
    for j, (name, parent) in enumerate(zip(skel.names, np.asarray(skel.parent))):
        if not Sdf.Path.IsValidIdentifier(name):
            raise TreegenError(f"skeleton joint {j}: name {name!r} is not a valid USD identifier")
        if parent >= j:
            raise TreegenError(f"skeleton joint {j}: parent {parent} does not come before it")
        paths.append(name if parent < 0 else f"{paths[parent]}/{name}")
    return paths


def _rest_matrices(skel: Skeleton) -> np.ndarray:
    """(J, 4, 4) column-vector rest matrices from the local translations and rotations."""
    t = np.asarray(skel.rest_translation, np.float64)
    m = np.zeros((len(t), 4, 4))
    if len(t):
        m[:, :3, :3] = to_matrix(skel.rest_rotation)
    m[:, :3, 3] = t
    m[:, 3, 3] = 1.0
    return m
