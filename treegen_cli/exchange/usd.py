"""Asset → UsdSkel (.usda text, .usdc crate, .usdz package), and a validator runner.

Writers only serialise: everything here is a re-encoding of the Asset. Stage layout:

    /<Asset>                       Xform, kind=component, defaultPrim
        Looks/bark, Looks/leaf     UsdPreviewSurface materials (+ an st primvar reader and a
                                   UsdUVTexture per Material texture: base colour, normal map)
        LODHeuristic               LODDistanceHeuristic (only with >1 LOD, not in a .usdz)
        LODs                       Xform with the variant set "LOD" (only with >1 LOD) and
                                   LODRootAPI (not in a .usdz: AR Quick Look rejects UsdLod)
            LOD0, LOD1, ...        SkelRoot: Skeleton, SkelAnimation(s), meshes
        (LOD0)                     with a single LOD the SkelRoot sits directly under /<Asset>

Textures (texture_files.py): a .usdz packages them (`textures/<name>.png`, after the root
layer); a .usda/.usdc gets flat siblings `<stem>_<name>.png`, which staging moves into place
like a .gltf's .bin. Asset paths are "./..." relative to the layer.

Up axis: metres and right-handed either way. "Z" (the default of .usda/.usdc) writes generator
space as it is; "Y" (the default of .usdz: AR Quick Look needs it) changes axes with
axes.Z_UP_TO_Y_UP in every point, normal, matrix, quaternion and box, so the stage is natively
Y up with no hidden root transform. USD matrices are row-vector (p' = p·M): every matrix here
is the transpose of the Asset's.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..asset import Asset, Clip, Lod, Material, Primitive, Skeleton, Texture, lod_bounds
from ..axes import matrix_to_y_up, quat_to_y_up, to_y_up
from ..errors import TreegenError
from ..quat import continuous, to_matrix
from .impostor_meta import describe, impostor_lod, write_sidecar
from .texture_files import TextureFiles

SUFFIXES = (".usda", ".usdc", ".usdz")
USDZ_MTIME = 946684800  # 2000-01-01: fixed zip entry time for reproducible .usdz bytes


# --------------------------------------------------------------------------- public API


def write_usd(asset: Asset, path) -> None:
    """Write `asset` to exactly `path` (plus its texture files); the suffix picks text, crate
    or a usdz package.

    The caller (exchange.export) stages it; a temp name with the right suffix works for all
    three formats.
    """
    path = Path(path)
    suffix = check_suffix(path)  # before the stage is built
    up = up_axis(asset.up_axis, suffix)
    textures = TextureFiles(path)
    stage = build_stage(asset, up, textures, lod_schemas=suffix != ".usdz")
    k = impostor_lod(asset)
    meta = None
    if k is not None:  # the atlas beside (or in) the file, described in its axes
        imp = asset.lods[k].impostor
        meta = describe(
            asset,
            k,
            Axes(up).points(np.eye(3)).T,
            {"albedo": textures.name(imp.albedo), "normal_depth": textures.name(imp.normal_depth)},
        )
        layer = stage.GetRootLayer()
        layer.customLayerData = dict(layer.customLayerData) | {
            "treegen_impostor": json.dumps(meta, sort_keys=True)
        }
    write_stage(stage, path, _identifier(asset.name) + ".usdc", textures.files)
    if meta is not None:
        write_sidecar(meta | {"file": path.name}, path)


def up_axis(requested: str | None, suffix: str) -> str:
    """ "Y" or "Z": the requested axis, else Y for a .usdz (AR Quick Look accepts only Y up)
    and Z (generator space, no conversion) for .usda/.usdc."""
    if requested is None:
        return "Y" if suffix == ".usdz" else "Z"
    up = str(requested).upper()
    if up not in ("Y", "Z"):
        raise TreegenError(f"up axis {requested!r}: expected y or z")
    return up


def check_suffix(path) -> str:
    """The lower-case USD suffix of `path`, or a TreegenError naming the allowed ones."""
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        raise TreegenError(f"{path}: unknown USD extension {suffix!r}; allowed {', '.join(SUFFIXES)}")
    return suffix


def write_stage(stage, path, inner_name: str, files: dict[str, bytes] | None = None) -> None:
    """Write a stage's root layer to exactly `path`: .usda text, .usdc crate, or a .usdz
    package whose first entry `inner_name` is the crate (the root layer must come first).

    files: relative name → bytes of the files the layer refers to (textures): written beside
    `path`, or packaged after the layer in name order."""
    from pxr import Sdf

    path = Path(path)
    suffix = check_suffix(path)
    layer = stage.GetRootLayer()
    files = files or {}
    if suffix in (".usda", ".usdc"):
        if not layer.Export(str(path), args={"format": suffix[1:]}):
            raise TreegenError(f"{path}: could not write the USD layer")
        for name, data in sorted(files.items()):
            (path.parent / name).write_bytes(data)
        return
    tmpdir = tempfile.mkdtemp(prefix="treegen-usdz-", dir=path.parent if path.parent.exists() else None)
    try:
        inner = os.path.join(tmpdir, inner_name)
        if not layer.Export(inner, args={"format": "usdc"}):
            raise TreegenError(f"{path}: could not write the USD layer")
        entries = [(inner, inner_name)]
        for name, data in sorted(files.items()):
            local = os.path.join(tmpdir, "files", name)
            os.makedirs(os.path.dirname(local), exist_ok=True)
            with open(local, "wb") as f:
                f.write(data)
            entries.append((local, name))
        writer = Sdf.ZipFileWriter.CreateNew(str(path))
        for local, name in entries:
            # a zip entry carries the file's mtime: pin it so the same stage gives the same bytes
            os.utime(local, (USDZ_MTIME, USDZ_MTIME))
            writer.AddFile(local, name)
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
        sets = [
            (prim.GetPath(), name, prim.GetVariantSets().GetVariantSet(name).GetVariantNames())
            for prim in stage.Traverse()
            for name in prim.GetVariantSets().GetNames()
        ]
        with Usd.EditContext(stage, stage.GetSessionLayer()):
            for prim_path, name, variants in sets:
                vset = stage.GetPrimAtPath(prim_path).GetVariantSets().GetVariantSet(name)
                for variant in variants:
                    vset.SetVariantSelection(variant)
                    run(f" [variant {prim_path}{{{name}={variant}}}]")
                vset.ClearVariantSelection()
    return messages


# --------------------------------------------------------------------------- stage building


def new_stage(name: str, documentation: str, kind, up: str = "Z"):
    """An in-memory stage (metres, up axis `up`) whose default prim is an Xform named after
    `name` with model kind `kind`; returns (stage, root path)."""
    from pxr import Sdf, Usd, UsdGeom

    stage = Usd.Stage.CreateInMemory()
    stage.GetRootLayer().documentation = documentation
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up == "Y" else UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root_path = Sdf.Path("/" + _identifier(name))
    root = UsdGeom.Xform.Define(stage, root_path).GetPrim()
    Usd.ModelAPI(root).SetKind(kind)
    stage.SetDefaultPrim(root)
    return stage, root_path


class Axes:
    """Generator space (Z up) → the stage's axes: identity for "Z" (values pass through
    untouched, so Z-up files keep their bytes), axes.Z_UP_TO_Y_UP for "Y"."""

    def __init__(self, up: str = "Z"):
        self.up = up
        self.y = up == "Y"

    def points(self, v: np.ndarray) -> np.ndarray:
        return to_y_up(v) if self.y else v

    def matrices(self, m: np.ndarray) -> np.ndarray:
        return matrix_to_y_up(m) if self.y else m

    def quats(self, q: np.ndarray) -> np.ndarray:
        return quat_to_y_up(q) if self.y else q

    def box(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        """An axis-aligned box stays one: C permutes axes and flips signs."""
        if not self.y:
            return lo, hi
        a, b = to_y_up(np.asarray(lo, np.float64)), to_y_up(np.asarray(hi, np.float64))
        return np.minimum(a, b), np.maximum(a, b)


def build_stage(
    asset: Asset,
    up: str = "Z",
    textures: TextureFiles | None = None,
    lod_schemas: bool = True,
    texture_prefix: str = "",
):
    """The whole asset as an in-memory stage (one anonymous layer).

    textures: names the material textures' files (None: the materials are written without
    textures); lod_schemas: author UsdLod's LODRootAPI and heuristic (not in a .usdz);
    texture_prefix: prepended to texture names (forest prototypes)."""
    from pxr import Kind

    if not asset.lods:
        raise TreegenError(f"asset {asset.name!r}: no LODs to write")
    axes = Axes(up)
    stage, root_path = new_stage(
        asset.name, "treegen: skinned Weber-Penn tree (UsdSkel)", Kind.Tokens.component, up
    )
    if asset.extras:
        stage.GetRootLayer().customLayerData = {
            "treegen": {str(k): str(v) for k, v in sorted(asset.extras.items())}
        }

    def texture_path(tex: Texture | None) -> str | None:
        """Layer-relative ("./textures/leaf.png"), never a search path."""
        return None if tex is None or textures is None else "./" + textures.name(tex, texture_prefix)

    materials = {
        m.name: _define_material(stage, root_path.AppendChild("Looks"), m, texture_path)
        for m in asset.materials
    }

    tcps = _stage_timing(stage, asset)

    if len(asset.lods) == 1:
        _define_lod(stage, root_path.AppendChild("LOD0"), asset.lods[0], asset, materials, tcps, axes)
    else:
        _define_lod_root(stage, root_path, asset, materials, tcps, axes, lod_schemas)
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


def _define_lod_root(
    stage, root_path, asset: Asset, materials, tcps, axes: Axes, lod_schemas: bool = True
) -> None:
    """LODs as children of an LODRootAPI prim, plus a "LOD" variant set on that same prim.
    Without `lod_schemas` (a .usdz) only the variant set: the portable switch.

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
        _define_lod(stage, lods_path.AppendChild(name), lod, asset, materials, tcps, axes)
        bounds.append(lod_bounds(lod))

    if lod_schemas:
        lod_root = UsdLod.RootAPI.Apply(lods_prim)
        lod_root.CreateLodDefaultIndexAttr(0)
        lod_root.CreateLodHeuristicsRel().SetTargets([heur_path])
        heur = UsdLod.DistanceHeuristic.Define(stage, heur_path)
        heur.CreateLodDomainAttr(UsdLod.Tokens.imaging)
        lo, hi = axes.box(*bounds[0])
        heur.CreateCenterAttr(_gf_vec3f(0.5 * (lo + hi)))  # LOD root space = tree space
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


def _define_lod(stage, path, lod: Lod, asset: Asset, materials, tcps, axes: Axes) -> None:
    """One SkelRoot: Skeleton, its SkelAnimation(s), and the skinned meshes."""
    from pxr import UsdSkel

    skel_root = UsdSkel.Root.Define(stage, path)
    if lod.bounds is None:
        raise ValueError(f"asset {asset.name!r}: not prepared (prepare.prepare before export)")
    lo, hi = axes.box(*lod.bounds)
    skel_root.CreateExtentAttr([_gf_vec3f(lo), _gf_vec3f(hi)])
    skel_path = path.AppendChild("Skeleton")
    joint_paths = _define_skeleton(stage, skel_path, lod.skeleton, axes)

    anim_paths = []
    used = {"Skeleton"}
    for clip in lod.clips:
        name = _unique(_identifier(clip.name), used)
        anim_paths.append(path.AppendChild(name))
        _define_animation(stage, anim_paths[-1], clip, lod.skeleton, joint_paths, tcps, axes)
    if anim_paths:
        binding = UsdSkel.BindingAPI.Apply(stage.GetPrimAtPath(skel_path))
        binding.CreateAnimationSourceRel().SetTargets([anim_paths[0]])

    for prim in lod.primitives:
        name = _unique(_identifier(prim.name), used)
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
    moving = np.flatnonzero(clip.animated)
    moving = moving if moving.size else np.zeros(1, np.int64)  # the timeline's tracks
    frames, rot = clip.timeline
    rot = continuous(axes.quats(rot))  # consecutive samples on one hemisphere: lerping importers are safe
    anim = UsdSkel.Animation.Define(stage, path)
    anim.CreateJointsAttr(Vt.TokenArray([joint_paths[j] for j in moving]))
    anim.CreateTranslationsAttr(
        Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(axes.points(skel.rest_translation[moving]), np.float32))
    )
    anim.CreateScalesAttr(Vt.Vec3hArray.FromNumpy(np.ones((len(moving), 3), np.float16)))
    rot_attr = anim.CreateRotationsAttr()
    codes = _snap(np.asarray(clip.times, np.float64)[frames] * (tcps or 1.0))
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


def _define_material(stage, looks_path, m: Material, texture_path=lambda tex: None):
    """UsdPreviewSurface; an st primvar reader wired to the material's frame:stPrimvarName
    interface input; a UsdUVTexture for each texture `texture_path` names a file for.

    Base texture: its rgb (times base_color, via the texture's scale, as glTF's factor) feeds
    diffuseColor; with an alpha_cutoff its alpha feeds opacity, cut at opacityThreshold.
    Normal texture: raw colour space, scale (2,2,2,1) and bias (-1,-1,-1,0) map 8-bit [0, 1]
    to the [-1, 1] tangent-space normal UsdPreviewSurface expects (OpenGL convention, +Y up,
    as the Asset's)."""
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
    st = reader.CreateOutput("result", Sdf.ValueTypeNames.Float2)

    base = texture_path(m.base_texture)
    if base is not None:
        tex = _define_texture(
            stage, mpath.AppendChild("baseTexture"), base, m.base_texture, st, scale=(r, g, b, a)
        )
        surf.GetInput("diffuseColor").ConnectToSource(tex.ConnectableAPI(), "rgb")
        if m.alpha_cutoff is not None:
            surf.GetInput("opacity").ConnectToSource(tex.ConnectableAPI(), "a")
    normal = texture_path(m.normal_texture)
    if normal is not None:
        tex = _define_texture(
            stage,
            mpath.AppendChild("normalTexture"),
            normal,
            m.normal_texture,
            st,
            scale=(2.0, 2.0, 2.0, 1.0),
            bias=(-1.0, -1.0, -1.0, 0.0),
        )
        surf.CreateInput("normal", Sdf.ValueTypeNames.Normal3f).ConnectToSource(tex.ConnectableAPI(), "rgb")
    return material


def _define_texture(stage, path, file: str, texture: Texture, st, scale, bias=None):
    """A UsdUVTexture reading `file` at the st reader's output; outputs rgb and a."""
    from pxr import Gf, Sdf, UsdShade

    wrap = "clamp" if texture.wrap.upper().startswith("CLAMP") else "repeat"
    tex = UsdShade.Shader.Define(stage, path)
    tex.CreateIdAttr("UsdUVTexture")
    tex.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(file))
    tex.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st)
    tex.CreateInput("wrapS", Sdf.ValueTypeNames.Token).Set(wrap)
    tex.CreateInput("wrapT", Sdf.ValueTypeNames.Token).Set(wrap)
    tex.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB" if texture.srgb else "raw")
    tex.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*map(float, scale)))
    if bias is not None:
        tex.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*map(float, bias)))
    tex.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    tex.CreateOutput("a", Sdf.ValueTypeNames.Float)
    return tex


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
