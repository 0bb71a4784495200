"""Asset → UsdSkel (.usda text, .usdc crate, .usdz package), and a validator runner.

Writers only serialise: everything here is a re-encoding of the Asset. Stage layout:

    /<Asset>                       Xform, kind=component, defaultPrim
        Looks/bark, Looks/leaf     UsdPreviewSurface materials (+ an st primvar reader)
        LODHeuristic               LODDistanceHeuristic (only with >1 LOD)
        LODs                       Xform with LODRootAPI and variant set "LOD" (only with >1 LOD)
            LOD0, LOD1, ...        SkelRoot: Skeleton, SkelAnimation(s), meshes
        (LOD0)                     with a single LOD the SkelRoot sits directly under /<Asset>

Generator space is Z up, metres, right-handed: upAxis "Z", metersPerUnit 1, no conversion.
USD matrices are row-vector (p' = p·M): every matrix here is the transpose of the Asset's.
"""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..asset import Asset, Clip, Lod, Material, Primitive, Skeleton, lod_bounds
from ..errors import TreegenError
from ..quat import continuous, to_matrix

SUFFIXES = (".usda", ".usdc", ".usdz")
USDZ_MTIME = 946684800  # 2000-01-01: fixed zip entry time for reproducible .usdz bytes


# --------------------------------------------------------------------------- public API

def write_usd(asset: Asset, path) -> None:
    """Write `asset` to exactly `path`; the suffix picks text, crate or a usdz package.

    The caller (exchange.export) stages it; a temp name with the right suffix works for all
    three formats.
    """
    check_suffix(path)                            # before the stage is built
    write_stage(build_stage(asset), path, _identifier(asset.name) + ".usdc")


def check_suffix(path) -> str:
    """The lower-case USD suffix of `path`, or a TreegenError naming the allowed ones."""
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise TreegenError(f"{path}: unknown USD extension {suffix!r}; allowed {', '.join(SUFFIXES)}")
    return suffix


def write_stage(stage, path, inner_name: str) -> None:
    """Write a stage's root layer to exactly `path`: .usda text, .usdc crate, or a .usdz
    package whose single entry `inner_name` is the crate (no external files to collect)."""
    from pxr import Sdf

    path = Path(path)
    suffix = check_suffix(path)
    layer = stage.GetRootLayer()
    if suffix in (".usda", ".usdc"):
        if not layer.Export(str(path), args={"format": suffix[1:]}):
            raise TreegenError(f"{path}: could not write the USD layer")
        return
    tmpdir = tempfile.mkdtemp(prefix="treegen-usdz-", dir=path.parent if path.parent.exists() else None)
    try:
        inner = os.path.join(tmpdir, inner_name)
        if not layer.Export(inner, args={"format": "usdc"}):
            raise TreegenError(f"{path}: could not write the USD layer")
        # the zip entry carries the file's mtime: pin it so the same stage gives the same bytes
        os.utime(inner, (USDZ_MTIME, USDZ_MTIME))
        writer = Sdf.ZipFileWriter.CreateNew(str(path))
        writer.AddFile(inner, inner_name)
        if not writer.Save():
            raise TreegenError(f"{path}: could not write the usdz package")
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)


def validate_usd(path, all_variants: bool = True) -> list[str]:
    """Run every validator registered with pxr.UsdValidation (core, geom, shade, skel, usdz
    utils, ...) over the stage at `path`; return their messages (empty list = clean).

    all_variants: also validate the stage under every selection of every variant set (our
    "LOD" set), set in the session layer, so non-default LODs are checked too.
    """
    from pxr import Usd, UsdValidation

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        return [f"{path}: cannot be opened as a USD stage"]
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    messages: list[str] = []

    def run(label: str) -> None:
        for e in context.Validate(stage):
            if not e.HasNoError():
                msg = e.GetErrorAsString() + label
                if msg not in messages:
                    messages.append(msg)

    run("")
    if all_variants:
        sets = [(prim.GetPath(), name, prim.GetVariantSets().GetVariantSet(name).GetVariantNames())
                for prim in stage.Traverse() for name in prim.GetVariantSets().GetNames()]
        with Usd.EditContext(stage, stage.GetSessionLayer()):
            for prim_path, name, variants in sets:
                vset = stage.GetPrimAtPath(prim_path).GetVariantSets().GetVariantSet(name)
                for variant in variants:
                    vset.SetVariantSelection(variant)
                    run(f" [variant {prim_path}{{{name}={variant}}}]")
                vset.ClearVariantSelection()
    return messages


# --------------------------------------------------------------------------- stage building

def new_stage(name: str, documentation: str, kind):
    """An in-memory stage in generator space (Z up, metres) whose default prim is an Xform
    named after `name` with model kind `kind`; returns (stage, root path)."""
    from pxr import Sdf, Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().documentation = documentation
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root_path = Sdf.Path("/" + _identifier(name))
    root = UsdGeom.Xform.Define(stage, root_path).GetPrim()
    Usd.ModelAPI(root).SetKind(kind)
    stage.SetDefaultPrim(root)
    return stage, root_path


def build_stage(asset: Asset):
    """The whole asset as an in-memory stage (one anonymous layer)."""
    from pxr import Kind

    if not asset.lods:
        raise TreegenError(f"asset {asset.name!r}: no LODs to write")
    stage, root_path = new_stage(asset.name, "treegen: skinned Weber-Penn tree (UsdSkel)",
                                 Kind.Tokens.component)
    if asset.extras:
        stage.GetRootLayer().customLayerData = {
            "treegen": {str(k): str(v) for k, v in sorted(asset.extras.items())}}

    materials = {m.name: _define_material(stage, root_path.AppendChild("Looks"), m)
                 for m in asset.materials}

    tcps = _stage_timing(stage, asset)

    if len(asset.lods) == 1:
        _define_lod(stage, root_path.AppendChild("LOD0"), asset.lods[0], asset, materials, tcps)
    else:
        _define_lod_root(stage, root_path, asset, materials, tcps)
    return stage


def _stage_timing(stage, asset: Asset) -> float | None:
    """timeCodesPerSecond = framesPerSecond = the clips' sample rate; start/end cover them."""
    clips = [c for lod in asset.lods for c in lod.clips if len(c.times)]
    if not clips:
        return None
    tcps = _sample_rate(clips[0].times)
    end = max(float(c.times[-1]) for c in clips) * tcps
    stage.SetTimeCodesPerSecond(tcps)
    stage.SetFramesPerSecond(tcps)
    stage.SetStartTimeCode(0.0)
    stage.SetEndTimeCode(_snap(np.array([end]))[0])
    return tcps


def _define_lod_root(stage, root_path, asset: Asset, materials, tcps) -> None:
    """LODs as children of an LODRootAPI prim, plus a "LOD" variant set on that same prim.

    Both views share one copy of the data: the LOD items are authored once, locally; each
    variant only toggles `visibility` (LODk: every other item invisible). The default selection
    LOD0 therefore gives legacy renderers exactly what the UsdLod docs recommend (default item
    visible, others invisible), while an LOD-aware renderer still sees every item active under
    the root and picks by the distance heuristic. Importers that read variant sets (Unreal)
    switch LODk to show only that item. `active` is not used for the toggle, because inactive
    items would vanish from the LOD root's children.
    """
    from pxr import UsdGeom, UsdLod, Vt

    lods_path = root_path.AppendChild("LODs")
    heur_path = root_path.AppendChild("LODHeuristic")
    lods_prim = UsdGeom.Xform.Define(stage, lods_path).GetPrim()
    names = [f"LOD{k}" for k in range(len(asset.lods))]
    bounds = []
    for name, lod in zip(names, asset.lods):
        _define_lod(stage, lods_path.AppendChild(name), lod, asset, materials, tcps)
        bounds.append(lod_bounds(lod))

    lod_root = UsdLod.RootAPI.Apply(lods_prim)
    lod_root.CreateLodDefaultIndexAttr(0)
    lod_root.CreateLodHeuristicsRel().SetTargets([heur_path])
    heur = UsdLod.DistanceHeuristic.Define(stage, heur_path)
    heur.CreateLodDomainAttr(UsdLod.Tokens.imaging)
    lo, hi = bounds[0]
    heur.CreateCenterAttr(_gf_vec3f(0.5 * (lo + hi)))   # LOD root space = tree space
    # thresholds: LOD k (k ≥ 1) is used from Lod.distance on
    heur.CreateThresholdsAttr(Vt.FloatArray([float(lod.distance) for lod in asset.lods[1:]]))

    vset = lods_prim.GetVariantSets().AddVariantSet("LOD")
    for k, name in enumerate(names):
        vset.AddVariant(name)
    for k, name in enumerate(names):
        vset.SetVariantSelection(name)
        with vset.GetVariantEditContext():
            for other in names:
                if other != name:
                    over = stage.OverridePrim(lods_path.AppendChild(other))
                    UsdGeom.Imageable(over).CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    vset.SetVariantSelection(names[0])
    # child order is the LOD index; variant overs would otherwise be composed first
    lods_prim.SetChildrenReorder(names)


def _define_lod(stage, path, lod: Lod, asset: Asset, materials, tcps) -> None:
    """One SkelRoot: Skeleton, its SkelAnimation(s), and the skinned meshes."""
    from pxr import UsdSkel

    skel_root = UsdSkel.Root.Define(stage, path)
    if lod.bounds is None:
        raise ValueError(f"asset {asset.name!r}: not prepared (prepare.prepare before export)")
    lo, hi = lod.bounds
    skel_root.CreateExtentAttr([_gf_vec3f(lo), _gf_vec3f(hi)])
    skel_path = path.AppendChild("Skeleton")
    joint_paths = _define_skeleton(stage, skel_path, lod.skeleton)

    anim_paths = []
    used = {"Skeleton"}
    for clip in lod.clips:
        name = _unique(_identifier(clip.name), used)
        anim_paths.append(path.AppendChild(name))
        _define_animation(stage, anim_paths[-1], clip, lod.skeleton, joint_paths, tcps)
    if anim_paths:
        binding = UsdSkel.BindingAPI.Apply(stage.GetPrimAtPath(skel_path))
        binding.CreateAnimationSourceRel().SetTargets([anim_paths[0]])

    for prim in lod.primitives:
        name = _unique(_identifier(prim.name), used)
        mat = next((m for m in asset.materials if m.name == prim.material), None)
        _define_mesh(stage, path.AppendChild(name), prim, skel_path,
                     materials.get(prim.material), mat, len(lod.skeleton.names))


def _define_skeleton(stage, path, skel: Skeleton) -> list[str]:
    """Joints as path tokens "j0", "j0/j1", ...; bind = world, rest = local (row-vector)."""
    from pxr import UsdSkel, Vt

    joint_paths = _joint_paths(skel)
    s = UsdSkel.Skeleton.Define(stage, path)
    s.CreateJointsAttr(Vt.TokenArray(joint_paths))
    s.CreateJointNamesAttr(Vt.TokenArray(list(skel.names)))
    bind = np.ascontiguousarray(np.transpose(np.asarray(skel.bind_world, np.float64), (0, 2, 1)))
    s.CreateBindTransformsAttr(Vt.Matrix4dArray.FromNumpy(bind))
    rest = _rest_matrices(skel)
    s.CreateRestTransformsAttr(Vt.Matrix4dArray.FromNumpy(np.ascontiguousarray(np.transpose(rest, (0, 2, 1)))))
    return joint_paths


def _define_animation(stage, path, clip: Clip, skel: Skeleton, joint_paths, tcps) -> None:
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
    moving = np.flatnonzero(clip.animated)
    moving = moving if moving.size else np.zeros(1, np.int64)     # the timeline's tracks
    frames, rot = clip.timeline
    rot = continuous(rot)        # consecutive samples on one hemisphere: lerping importers are safe
    anim = UsdSkel.Animation.Define(stage, path)
    anim.CreateJointsAttr(Vt.TokenArray([joint_paths[j] for j in moving]))
    anim.CreateTranslationsAttr(Vt.Vec3fArray.FromNumpy(
        np.ascontiguousarray(skel.rest_translation[moving], np.float32)))
    anim.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((len(moving), 3), np.float16)))
    rot_attr = anim.CreateRotationsAttr()
    codes = _snap(np.asarray(clip.times, np.float64)[frames] * (tcps or 1.0))
    # Vt.QuatfArray.FromNumpy takes rows in GfQuatf memory order (x, y, z, w): the Asset's order
    for code, q in zip(codes, rot):
        rot_attr.Set(Vt.QuatfArray.FromNumpy(np.ascontiguousarray(q, np.float32)), float(code))
    anim.GetPrim().SetCustomDataByKey("treegen:interpolation", clip.interpolation)


def _define_mesh(stage, path, prim: Primitive, skel_path, material, mat: Material | None,
                 n_joints: int) -> None:
    """Triangle mesh with vertex normals, st, skinning primvars and a material binding."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade, UsdSkel, Vt

    pos = np.ascontiguousarray(prim.positions, np.float32)
    idx = np.asarray(prim.indices, np.int64)
    if idx.size % 3 or (idx.size and (idx.min() < 0 or idx.max() >= len(pos))):
        raise TreegenError(f"primitive {prim.name!r}: indices are not a valid triangle list")
    joints = np.asarray(prim.joints, np.int64)
    if joints.size and joints.max() >= n_joints:
        raise TreegenError(f"primitive {prim.name!r}: joint index beyond the skeleton")

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)   # Asset winding: CCW = front
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(pos))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(idx.size // 3, 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(idx.astype(np.int32)))
    mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(prim.normals, np.float32)))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
    if len(pos):
        mesh.CreateExtentAttr([Gf.Vec3f(*map(float, pos.min(0))), Gf.Vec3f(*map(float, pos.max(0)))])
    st = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                 UsdGeom.Tokens.vertex)
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


def _define_material(stage, looks_path, m: Material):
    """UsdPreviewSurface with constant inputs; an st primvar reader, wired to the material's
    frame:stPrimvarName interface input, is the slot a UsdUVTexture can plug into later."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade

    if not stage.GetPrimAtPath(looks_path):
        UsdGeom.Scope.Define(stage, looks_path)
    mpath = looks_path.AppendChild(_identifier(m.name))
    material = UsdShade.Material.Define(stage, mpath)
    st_name = material.CreateInput("frame:stPrimvarName", Sdf.ValueTypeNames.String)
    st_name.Set("st")

    surf = UsdShade.Shader.Define(stage, mpath.AppendChild("PreviewSurface"))
    surf.CreateIdAttr("UsdPreviewSurface")
    r, g, b, a = (float(c) for c in m.base_color)
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(r, g, b))
    surf.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(m.roughness))
    surf.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(float(m.metallic))
    surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(a)
    if m.alpha_cutoff is not None:
        surf.CreateInput("opacityThreshold", Sdf.ValueTypeNames.Float).Set(float(m.alpha_cutoff))
    material.CreateSurfaceOutput().ConnectToSource(surf.ConnectableAPI(), "surface")

    reader = UsdShade.Shader.Define(stage, mpath.AppendChild("stReader"))
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).ConnectToSource(st_name)
    reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)
    return material


# --------------------------------------------------------------------------- numeric helpers

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


def _sample_rate(times: np.ndarray) -> float:
    """Keys per second of a uniformly sampled clip (snapped to an integer when it is one)."""
    times = np.asarray(times, np.float64)
    if len(times) < 2 or times[-1] <= times[0]:
        return 24.0
    rate = (len(times) - 1) / (times[-1] - times[0])
    return float(round(rate)) if abs(rate - round(rate)) < 1e-6 else float(rate)


def _snap(codes: np.ndarray) -> np.ndarray:
    """Round time codes that are integers up to float noise, so files carry clean frames."""
    r = np.round(codes)
    return np.where(np.abs(codes - r) < 1e-6, r, codes)


def _gf_vec3f(v):
    from pxr import Gf
    return Gf.Vec3f(*(float(x) for x in v))


def _identifier(name: str) -> str:
    from pxr import Tf
    return Tf.MakeValidIdentifier(name or "tree")


def _unique(name: str, used: set[str]) -> str:
    out, k = name, 1
    while out in used:
        out, k = f"{name}_{k}", k + 1
    used.add(out)
    return out
