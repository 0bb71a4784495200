"""USD writer: files re-read through pxr (UsdSkel queries, UsdValidation, UsdLod) must say
what the Asset says."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import pxr  # noqa: E402,F401  (usd-core is a dependency: a missing pxr fails loudly)
from pxr import Gf, Usd, UsdGeom, UsdLod, UsdShade, UsdSkel, Vt  # noqa: E402

from synthetic import synthetic_asset  # noqa: E402
from treegen_cli.axes import to_y_up  # noqa: E402
from treegen_cli.errors import TreegenError  # noqa: E402
from treegen_cli.exchange.usd import write_usd as _write_usd  # noqa: E402
from treegen_cli.exchange.validate import validate_usd  # noqa: E402
from treegen_cli.prepare import prepare  # noqa: E402

FORMATS = ("usda", "usdc", "usdz")


def write_usd(asset, path, **opts):
    """Hand-built assets go through the prepare stage, as the pipeline's do."""
    return _write_usd(prepare(asset, bounds=True), path, **opts)


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """{(lods, fmt): path} for the synthetic asset with 1 and 3 LODs in every format."""
    d = tmp_path_factory.mktemp("usd")
    out = {}
    for lods in (1, 3):
        asset = synthetic_asset(lods=lods)
        for fmt in FORMATS:
            out[lods, fmt] = d / f"tree{lods}.{fmt}"
            write_usd(asset, out[lods, fmt])
    return out


def stage_axes(stage, v):
    """Generator-space (Z up) vectors as the stage stores them: a Y-up stage (a .usdz by
    default) holds them through axes.to_y_up."""
    v = np.asarray(v, np.float64)
    return to_y_up(v) if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y else v


def lod_paths(stage, n_lods):
    root = stage.GetDefaultPrim().GetPath()
    if n_lods == 1:
        return [root.AppendChild("LOD0")]
    return [root.AppendPath(f"LODs/LOD{k}") for k in range(n_lods)]


def skel_query(stage, skel_root_path):
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetPrimAtPath(skel_root_path))
    cache.Populate(root, Usd.PrimDefaultPredicate)
    (binding,) = cache.ComputeSkelBindings(root, Usd.PrimDefaultPredicate)
    return cache.GetSkelQuery(binding.GetSkeleton()), binding


def expected_playback(clip, frame, joint):
    """What the Asset's track of `joint` plays at key index `frame` (slerp or hold)."""
    if clip.keys is None:
        return clip.rotations[frame, joint]
    kept = np.asarray(clip.keys[joint])
    a = kept[np.searchsorted(kept, frame, side="right") - 1]
    if a == frame or clip.interpolation == "STEP":
        return clip.rotations[a, joint]
    b = kept[np.searchsorted(kept, frame, side="right")]
    u = (clip.times[frame] - clip.times[a]) / (clip.times[b] - clip.times[a])
    r0, r1 = Rotation.from_quat(clip.rotations[a, joint]), Rotation.from_quat(clip.rotations[b, joint])
    return (r0 * Rotation.from_rotvec(u * (r0.inv() * r1).as_rotvec())).as_quat()


def local_rotations(skel_q, code):
    """xyzw quaternions of every joint's local transform at a time code, via UsdSkel."""
    mats = np.array(skel_q.ComputeJointLocalTransforms(Usd.TimeCode(code)))
    return Rotation.from_matrix(np.transpose(mats[:, :3, :3], (0, 2, 1))).as_quat()


def same_rotation(q, r, atol=1e-5):
    return abs(abs(float(np.dot(q, r))) - 1.0) < atol


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("lods", [1, 3])
def test_validators_report_nothing(written, lods, fmt):
    assert validate_usd(written[lods, fmt]) == []


def test_validator_catches_a_broken_stage(tmp_path):
    """validate_usd is not vacuous: a stage without upAxis/metersPerUnit is reported."""
    bad = tmp_path / "bad.usda"
    stage = Usd.Stage.CreateNew(str(bad))
    UsdGeom.Xform.Define(stage, "/x")
    stage.Save()
    msgs = validate_usd(bad)
    assert any("upAxis" in m for m in msgs) and any("metersPerUnit" in m for m in msgs)


@pytest.mark.parametrize("fmt", FORMATS)
def test_stage_metadata(written, fmt):
    stage = Usd.Stage.Open(str(written[3, fmt]))
    # .usdz defaults to Y up (AR Quick Look), .usda/.usdc keep generator space
    assert UsdGeom.GetStageUpAxis(stage) == (UsdGeom.Tokens.y if fmt == "usdz" else UsdGeom.Tokens.z)
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetName() == "synthetic"
    clip = synthetic_asset().lods[0].clips[0]
    rate = (len(clip.times) - 1) / clip.times[-1]
    assert stage.GetTimeCodesPerSecond() == stage.GetFramesPerSecond() == rate
    assert stage.GetStartTimeCode() == 0
    assert stage.GetEndTimeCode() == pytest.approx(clip.times[-1] * rate)


@pytest.mark.parametrize("lods", [1, 3])
def test_skeleton_round_trip(written, lods):
    asset = synthetic_asset(lods=lods)
    stage = Usd.Stage.Open(str(written[lods, "usdc"]))
    for path, lod in zip(lod_paths(stage, lods), asset.lods):
        skel = UsdSkel.Skeleton(stage.GetPrimAtPath(path.AppendChild("Skeleton")))
        joints = list(skel.GetJointsAttr().Get())
        assert len(joints) == len(lod.skeleton.names)
        assert joints[0] == "j0"
        for j, p in enumerate(joints[1:], 1):  # each joint's parent path is an earlier joint
            parent = p.rsplit("/", 1)[0]
            assert parent in joints[:j]
            assert joints.index(parent) == lod.skeleton.parent[j]
        bind = np.array(skel.GetBindTransformsAttr().Get())
        np.testing.assert_allclose(np.transpose(bind, (0, 2, 1)), lod.skeleton.bind_world, atol=1e-12)
        rest = np.array(skel.GetRestTransformsAttr().Get())
        np.testing.assert_allclose(rest[:, 3, :3], lod.skeleton.rest_translation, atol=1e-12)
        rq = Rotation.from_matrix(np.transpose(rest[:, :3, :3], (0, 2, 1))).as_quat()
        assert all(same_rotation(a, b, 1e-9) for a, b in zip(rq, lod.skeleton.rest_rotation))


@pytest.mark.parametrize("fmt", FORMATS)
def test_meshes_round_trip(written, fmt):
    asset = synthetic_asset(lods=3)
    stage = Usd.Stage.Open(str(written[3, fmt]))
    for path, lod in zip(lod_paths(stage, 3), asset.lods):
        for prim in lod.primitives:
            mesh = UsdGeom.Mesh(stage.GetPrimAtPath(path.AppendChild(prim.name)))
            assert len(mesh.GetPointsAttr().Get()) == len(prim.positions)
            counts = np.array(mesh.GetFaceVertexCountsAttr().Get())
            assert len(counts) == len(prim.indices) // 3 and (counts == 3).all()
            np.testing.assert_array_equal(mesh.GetFaceVertexIndicesAttr().Get(), prim.indices)
            assert mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.rightHanded
            assert mesh.GetNormalsInterpolation() == UsdGeom.Tokens.vertex
            np.testing.assert_allclose(
                mesh.GetNormalsAttr().Get(), stage_axes(stage, prim.normals), atol=1e-7
            )
            np.testing.assert_allclose(
                mesh.GetPointsAttr().Get(), stage_axes(stage, prim.positions), atol=1e-6
            )
            st = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
            assert st.GetTypeName() == "texCoord2f[]"
            np.testing.assert_allclose(st.Get(), prim.uvs)
            material = next(m for m in asset.materials if m.name == prim.material)
            assert mesh.GetDoubleSidedAttr().Get() == material.double_sided
            bound, _ = UsdShade.MaterialBindingAPI(mesh.GetPrim()).ComputeBoundMaterial()
            assert bound.GetPrim().GetName() == prim.material
            surface = bound.ComputeSurfaceSource()[0]
            assert surface.GetIdAttr().Get() == "UsdPreviewSurface"
            color = surface.GetInput("diffuseColor").Get()
            np.testing.assert_allclose(color, material.base_color[:3], atol=1e-7)

            binding = UsdSkel.BindingAPI(mesh.GetPrim())
            ji, jw = binding.GetJointIndicesPrimvar(), binding.GetJointWeightsPrimvar()
            assert ji.GetElementSize() == jw.GetElementSize() == 4
            assert ji.GetInterpolation() == jw.GetInterpolation() == UsdGeom.Tokens.vertex
            w = np.array(jw.Get()).reshape(-1, 4)
            np.testing.assert_allclose(w.sum(1), 1.0, atol=1e-6)
            np.testing.assert_array_equal(np.array(ji.Get()).reshape(-1, 4), prim.joints)
            assert binding.GetSkeletonRel().GetTargets() == [path.AppendChild("Skeleton")]
            assert binding.GetGeomBindTransformAttr().Get() == Gf.Matrix4d(1.0)


@pytest.mark.parametrize("lods", [1, 3])
def test_skinned_rest_pose_equals_asset(written, lods):
    """UsdSkel skinning with the rest pose reproduces the Asset's rest positions."""
    asset = synthetic_asset(lods=lods)
    stage = Usd.Stage.Open(str(written[lods, "usda"]))
    for path, lod in zip(lod_paths(stage, lods), asset.lods):
        sq, binding = skel_query(stage, path)
        rest = sq.ComputeJointSkelTransforms(Usd.TimeCode.Default(), True)
        bind = sq.GetJointWorldBindTransforms()
        xforms = Vt.Matrix4dArray([bind[j].GetInverse() * rest[j] for j in range(len(rest))])
        targets = {t.GetPrim().GetName(): t for t in binding.GetSkinningTargets()}
        assert set(targets) == {p.name for p in lod.primitives}
        for prim in lod.primitives:
            pts = Vt.Vec3fArray(UsdGeom.Mesh(targets[prim.name].GetPrim()).GetPointsAttr().Get())
            assert targets[prim.name].ComputeSkinnedPoints(xforms, pts, Usd.TimeCode.Default())
            np.testing.assert_allclose(np.array(pts), prim.positions, atol=1e-5)


def test_animation_rotations_match_clip(written):
    """Local joint rotations UsdSkel computes at every frame equal the clip's playback
    (sparse keys included: frames between kept keys are slerped)."""
    asset = synthetic_asset(lods=3)
    stage = Usd.Stage.Open(str(written[3, "usdc"]))
    for path, lod in zip(lod_paths(stage, 3), asset.lods):
        sq, _ = skel_query(stage, path)
        clip = lod.clips[0]
        anim = UsdSkel.Skeleton(sq.GetPrim()).GetPrim().GetRelationship("skel:animationSource")
        assert anim.GetTargets() == [path.AppendChild(clip.name)]
        for frame in range(len(clip.times)):
            got = local_rotations(sq, frame)
            for j in range(len(lod.skeleton.names)):
                assert same_rotation(got[j], expected_playback(clip, frame, j)), (path, frame, j)


def test_animated_skinning_matches_numpy_lbs(written):
    """Skinned points at a frame between kept keys equal forward kinematics + linear blend
    skinning done here in numpy from the Asset."""
    asset = synthetic_asset(lods=1)
    lod = asset.lods[0]
    clip, skel = lod.clips[0], lod.skeleton
    stage = Usd.Stage.Open(str(written[1, "usdz"]))
    sq, binding = skel_query(stage, lod_paths(stage, 1)[0])
    frame = 3
    world = np.empty((len(skel.names), 4, 4))
    for j in range(len(skel.names)):
        local = np.eye(4)
        local[:3, :3] = Rotation.from_quat(expected_playback(clip, frame, j)).as_matrix()
        local[:3, 3] = skel.rest_translation[j]
        world[j] = local if skel.parent[j] < 0 else world[skel.parent[j]] @ local
    skin = world @ np.linalg.inv(skel.bind_world)
    xforms = sq.ComputeSkinningTransforms(Usd.TimeCode(frame))
    targets = {t.GetPrim().GetName(): t for t in binding.GetSkinningTargets()}
    for prim in lod.primitives:
        p = np.c_[prim.positions, np.ones(len(prim.positions))]
        moved = np.einsum("vk,vkij,vj->vi", prim.weights, skin[prim.joints], p)[:, :3]
        pts = Vt.Vec3fArray(UsdGeom.Mesh(targets[prim.name].GetPrim()).GetPointsAttr().Get())
        assert targets[prim.name].ComputeSkinnedPoints(xforms, pts, Usd.TimeCode(frame))
        assert np.abs(moved - prim.positions).max() > 0.01  # it really moves
        np.testing.assert_allclose(np.array(pts), stage_axes(stage, moved), atol=1e-4)


def test_step_clip_holds_between_kept_keys(tmp_path):
    asset = synthetic_asset(lods=1)
    lod = asset.lods[0]
    clip = dataclasses.replace(lod.clips[0], interpolation="STEP")
    asset = dataclasses.replace(asset, lods=[dataclasses.replace(lod, clips=[clip])])
    path = tmp_path / "step.usda"
    write_usd(asset, path)
    assert validate_usd(path) == []
    stage = Usd.Stage.Open(str(path))
    sq, _ = skel_query(stage, lod_paths(stage, 1)[0])
    for frame in range(len(clip.times)):
        got = local_rotations(sq, frame)
        for j in range(len(lod.skeleton.names)):
            held = clip.rotations[max(k for k in clip.keys[j] if k <= frame), j]
            assert same_rotation(got[j], held), (frame, j)


def test_lod_root_and_variant_set(written):
    asset = synthetic_asset(lods=3)
    stage = Usd.Stage.Open(str(written[3, "usda"]))
    lods_prim = stage.GetDefaultPrim().GetChild("LODs")
    assert lods_prim.HasAPI(UsdLod.RootAPI)
    items = [p.GetName() for p in UsdLod.RootAPI(lods_prim).GetPrim().GetChildren()]
    assert items == ["LOD0", "LOD1", "LOD2"]
    (heur_path,) = UsdLod.RootAPI(lods_prim).GetLodHeuristicsRel().GetTargets()
    heur = UsdLod.DistanceHeuristic(stage.GetPrimAtPath(heur_path))
    assert list(heur.GetThresholdsAttr().Get()) == [lod.distance for lod in asset.lods[1:]]
    vset = lods_prim.GetVariantSets().GetVariantSet("LOD")
    assert vset.GetVariantNames() == ["LOD0", "LOD1", "LOD2"]
    for k in range(3):
        vset.SetVariantSelection(f"LOD{k}")
        vis = [
            UsdGeom.Imageable(stage.GetPrimAtPath(lods_prim.GetPath().AppendChild(n))).ComputeVisibility()
            for n in items
        ]
        assert vis == [UsdGeom.Tokens.inherited if i == k else UsdGeom.Tokens.invisible for i in range(3)]
        assert all(stage.GetPrimAtPath(lods_prim.GetPath().AppendChild(n)).IsActive() for n in items)


def test_single_lod_has_no_lod_root(written):
    stage = Usd.Stage.Open(str(written[1, "usda"]))
    root = stage.GetDefaultPrim()
    assert root.GetChild("LOD0").IsA(UsdSkel.Root)
    assert not root.GetChild("LODs")


@pytest.mark.parametrize("fmt", FORMATS)
def test_same_asset_same_bytes(tmp_path, fmt):
    a, b = tmp_path / f"a.{fmt}", tmp_path / f"b.{fmt}"
    write_usd(synthetic_asset(lods=3), a)
    write_usd(synthetic_asset(lods=3), b)
    assert a.read_bytes() == b.read_bytes()


def test_usdz_under_a_temp_name(tmp_path):
    """The exchange registry writes to a temp name with the same suffix, then renames."""
    tmp = tmp_path / ".tree.usdz.tmp-123.usdz"
    write_usd(synthetic_asset(lods=1), tmp)
    final = tmp_path / "tree.usdz"
    tmp.rename(final)
    assert validate_usd(final) == []
    assert Usd.Stage.Open(str(final)).GetDefaultPrim().GetName() == "synthetic"


def test_accented_names_become_ascii_prim_names(tmp_path):
    """`palmé` is the prim `palme`, not `palm__` (its é as two UTF-8 bytes); the file validates."""
    from dataclasses import replace

    path = tmp_path / "palme.usda"
    write_usd(replace(synthetic_asset(lods=1), name="palmé"), path)
    assert validate_usd(path) == []
    assert Usd.Stage.Open(str(path)).GetDefaultPrim().GetName() == "palme"
    write_usd(replace(synthetic_asset(lods=1), name="123tree"), path)  # a leading digit: kept
    assert Usd.Stage.Open(str(path)).GetDefaultPrim().GetName() == "_123tree"  # (was _23tree)


def test_no_clip_writes_a_static_skinned_tree(tmp_path):
    path = tmp_path / "static.usdc"
    write_usd(synthetic_asset(lods=1, with_clip=False), path)
    assert validate_usd(path) == []
    stage = Usd.Stage.Open(str(path))
    assert not [p for p in stage.Traverse() if p.IsA(UsdSkel.Animation)]


def test_unknown_suffix_is_a_user_error(tmp_path):
    with pytest.raises(TreegenError, match="usdz"):
        write_usd(synthetic_asset(), tmp_path / "tree.usdx")
    assert not list(tmp_path.iterdir())


def test_extra_clips_are_sibling_animations_and_empty_primitives_are_valid(tmp_path):
    """Only the first clip drives the skeleton; a primitive without vertices stays valid."""
    asset = synthetic_asset(lods=1)
    lod = asset.lods[0]
    calm = dataclasses.replace(
        lod.clips[0], name="calm", keys=None, rotations=np.repeat(lod.skeleton.rest_rotation[None], 9, 0)
    )
    empty = dataclasses.replace(
        lod.primitives[1],
        name="twigs",
        positions=np.zeros((0, 3), np.float32),
        normals=np.zeros((0, 3), np.float32),
        uvs=np.zeros((0, 2), np.float32),
        indices=np.zeros(0, np.uint32),
        joints=np.zeros((0, 4), np.uint16),
        weights=np.zeros((0, 4), np.float32),
    )
    lod = dataclasses.replace(lod, clips=[lod.clips[0], calm], primitives=[*lod.primitives, empty])
    path = tmp_path / "two clips.usda"
    write_usd(dataclasses.replace(asset, name="two clips", lods=[lod]), path)
    assert validate_usd(path) == []
    stage = Usd.Stage.Open(str(path))
    skel_root = stage.GetDefaultPrim().GetChild("LOD0")
    anims = [p.GetName() for p in skel_root.GetChildren() if p.IsA(UsdSkel.Animation)]
    assert anims == ["wind_lod0", "calm"]
    source = skel_root.GetChild("Skeleton").GetRelationship("skel:animationSource").GetTargets()
    assert source == [skel_root.GetPath().AppendChild("wind_lod0")]
    assert len(UsdGeom.Mesh(skel_root.GetChild("twigs")).GetPointsAttr().Get()) == 0


def test_validator_looks_inside_non_default_variants(tmp_path):
    path = tmp_path / "variants.usda"
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    root = UsdGeom.Xform.Define(stage, "/a").GetPrim()
    stage.SetDefaultPrim(root)
    vset = root.GetVariantSets().AddVariantSet("LOD")
    vset.AddVariant("LOD0")
    vset.AddVariant("LOD1")
    vset.SetVariantSelection("LOD1")
    with vset.GetVariantEditContext():  # a binding without MaterialBindingAPI, only in LOD1
        UsdGeom.Mesh.Define(stage, "/a/m").GetPrim().CreateRelationship("material:binding").SetTargets(["/a"])
    vset.SetVariantSelection("LOD0")
    stage.Save()
    assert validate_usd(path, all_variants=False) == []
    (msg,) = validate_usd(path)
    assert "MaterialBindingAPI" in msg and "LOD=LOD1" in msg


def test_usd_and_gltf_agree(tmp_path):
    """Same Asset through both writers: the USD skinned rest pose equals the glTF rest geometry
    (brought back to Z up) and both animate the same joints with the same rotations."""
    from treegen_cli.exchange import export as _export

    def export(a, p):
        return _export(prepare(a), p)

    from treegen_cli.axes import quat_to_y_up
    from treegen_cli.exchange.gltf_container import read_accessor, read_gltf

    asset = synthetic_asset(lods=1)
    export(asset, tmp_path / "t.glb")
    export(asset, tmp_path / "t.usdc")
    gltf, blob = read_gltf(tmp_path / "t.glb")
    stage = Usd.Stage.Open(str(tmp_path / "t.usdc"))
    sq, binding = skel_query(stage, lod_paths(stage, 1)[0])

    rest = sq.ComputeJointSkelTransforms(Usd.TimeCode.Default(), True)
    bind = sq.GetJointWorldBindTransforms()
    xforms = Vt.Matrix4dArray([bind[j].GetInverse() * rest[j] for j in range(len(rest))])
    targets = {t.GetPrim().GetName(): t for t in binding.GetSkinningTargets()}
    for mesh in gltf["meshes"]:
        for gprim in mesh["primitives"]:
            y_up = read_accessor(gltf, blob, gprim["attributes"]["POSITION"])
            z_up = np.stack([y_up[:, 0], -y_up[:, 2], y_up[:, 1]], -1)
            name = asset.materials[gprim["material"]].name
            prim = next(p for p in asset.lods[0].primitives if p.material == name)
            pts = Vt.Vec3fArray(UsdGeom.Mesh(targets[prim.name].GetPrim()).GetPointsAttr().Get())
            targets[prim.name].ComputeSkinnedPoints(xforms, pts, Usd.TimeCode.Default())
            np.testing.assert_allclose(np.array(pts), z_up, atol=1e-5)

    joint_nodes = gltf["skins"][0]["joints"]
    (anim,) = gltf["animations"]
    usd_anim = UsdSkel.Animation(
        stage.GetPrimAtPath(lod_paths(stage, 1)[0].AppendChild(asset.lods[0].clips[0].name))
    )
    gltf_joints = sorted(joint_nodes.index(c["target"]["node"]) for c in anim["channels"])
    usd_joints = [list(sq.GetJointOrder()).index(p) for p in usd_anim.GetJointsAttr().Get()]
    assert gltf_joints == sorted(usd_joints)
    rate = stage.GetTimeCodesPerSecond()
    for channel in anim["channels"]:
        sampler = anim["samplers"][channel["sampler"]]
        j = joint_nodes.index(channel["target"]["node"])
        times = read_accessor(gltf, blob, sampler["input"])
        values = read_accessor(gltf, blob, sampler["output"])
        for t, q in zip(times, values):
            usd_q = quat_to_y_up(local_rotations(sq, float(np.round(t * rate, 4)))[j])
            assert same_rotation(usd_q, q), (j, t)


def test_rotation_samples_stay_on_one_hemisphere(tmp_path):
    """A clip whose stored quaternions flip sign every key is written sign-continuous."""
    asset = synthetic_asset(lods=1)
    lod = asset.lods[0]
    clip = lod.clips[0]
    flipped = clip.rotations * np.where(np.arange(len(clip.times)) % 2, -1.0, 1.0)[:, None, None]
    lod = dataclasses.replace(lod, clips=[dataclasses.replace(clip, rotations=flipped, keys=None)])
    path = tmp_path / "flip.usda"
    write_usd(dataclasses.replace(asset, lods=[lod]), path)
    stage = Usd.Stage.Open(str(path))
    attr = UsdSkel.Animation(
        stage.GetPrimAtPath(lod_paths(stage, 1)[0].AppendChild(clip.name))
    ).GetRotationsAttr()
    samples = np.array([np.array(attr.Get(t)) for t in attr.GetTimeSamples()])
    assert len(samples) == len(clip.times)
    assert (np.einsum("kji,kji->kj", samples[1:], samples[:-1]) > 0).all()


def test_skel_root_extent_holds_every_animated_frame(written):
    asset = synthetic_asset(lods=3)
    stage = Usd.Stage.Open(str(written[3, "usdc"]))
    for path, lod in zip(lod_paths(stage, 3), asset.lods):
        lo, hi = np.array(UsdSkel.Root(stage.GetPrimAtPath(path)).GetExtentAttr().Get())
        sq, binding = skel_query(stage, path)
        for frame in range(len(lod.clips[0].times) * 2 - 1):  # keys and half-way between
            code = frame / 2
            xforms = sq.ComputeSkinningTransforms(Usd.TimeCode(code))
            for target in binding.GetSkinningTargets():
                pts = Vt.Vec3fArray(UsdGeom.Mesh(target.GetPrim()).GetPointsAttr().Get())
                target.ComputeSkinnedPoints(xforms, pts, Usd.TimeCode(code))
                p = np.array(pts)
                assert (p >= lo - 1e-5).all() and (p <= hi + 1e-5).all(), (path, code)


# --------------------------------------------------------------------------- textures, AR, axes

from synthetic import synthetic_textures, textured_asset  # noqa: E402
import arkit_check  # noqa: E402

ARKIT_PRIM_TYPES = {
    "",
    "Scope",
    "Xform",
    "Material",
    "Shader",
    "Mesh",
    "SkelRoot",
    "Skeleton",
    "SkelAnimation",
    "GeomSubset",
}  # the subset of ARKit's list trees need


@pytest.fixture(scope="module")
def textured(tmp_path_factory):
    """{(lods, fmt): path} for the textured synthetic asset, written through exchange.export
    (staged, texture siblings moved with the main file)."""
    from treegen_cli.exchange import export

    d = tmp_path_factory.mktemp("usd_tex")
    out = {}
    for lods in (1, 3):
        asset = prepare(textured_asset(lods=lods))
        for fmt in FORMATS:
            out[lods, fmt] = export(asset, d / f"tree{lods}.{fmt}")
    return out


def shader(stage, material, name):
    return UsdShade.Shader(
        stage.GetPrimAtPath(stage.GetDefaultPrim().GetPath().AppendPath(f"Looks/{material}/{name}"))
    )


def source(inp):
    """(shader prim name, output name) an input is connected to."""
    src, out, _ = inp.GetConnectedSource()
    return src.GetPrim().GetName(), out


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("lods", [1, 3])
def test_textured_files_validate(textured, lods, fmt):
    assert validate_usd(textured[lods, fmt][0]) == []


@pytest.mark.parametrize("lods", [1, 3])
def test_usdz_passes_arkit_compliance_checker(textured, lods):
    """usd-core's ComplianceChecker(arkit=True) (from usd-core 24.11: see tests/arkit_check.py)
    reports no error and no failed check: Y up, supported prim types, packaged textures,
    normal map encoding, shader ids and connections."""
    if not arkit_check.available():
        pytest.skip("usd-core 24.11 ComplianceChecker not installed: python tests/arkit_check.py --install")
    report = arkit_check.check(textured[lods, "usdz"][0])
    assert report["errors"] == [] and report["failed"] == [], report


def test_arkit_checker_is_not_vacuous(tmp_path):
    """A Z-up .usdz with UsdLod prims fails the checker the way the issue reported."""
    if not arkit_check.available():
        pytest.skip("usd-core 24.11 ComplianceChecker not installed: python tests/arkit_check.py --install")
    from treegen_cli.exchange.usd import build_stage
    from treegen_cli.exchange.usd_stage import write_stage

    path = tmp_path / "z.usdz"
    stage = build_stage(prepare(synthetic_asset(lods=3), bounds=True), "Z", None, lod_schemas=True)
    write_stage(stage, path, "z.usdc")
    failed = " ".join(arkit_check.check(path)["failed"])
    assert "upAxis" in failed and "LODDistanceHeuristic" in failed


@pytest.mark.parametrize("lods", [1, 3])
def test_usdz_is_ar_ready_in_process(textured, lods):
    """The AR Quick Look rules again with the project's own usd-core (runs without the side
    install): Y up, metres, only ARKit prim types and no UsdLod schema, shader ids ARKit knows,
    and every asset path resolves inside the package."""
    from pxr import Ar

    path = textured[lods, "usdz"][0]
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    prims = list(Usd.PrimRange.Stage(stage, Usd.TraverseInstanceProxies(Usd.PrimAllPrimsPredicate)))
    assert {p.GetTypeName() for p in prims} <= ARKIT_PRIM_TYPES
    assert not any(p.HasAPI(UsdLod.RootAPI) for p in prims)
    files = []
    for p in prims:
        if p.IsA(UsdShade.Shader):
            sid = UsdShade.Shader(p).GetShaderId()
            assert sid in ("UsdPreviewSurface", "UsdUVTexture") or sid.startswith("UsdPrimvarReader")
            f = UsdShade.Shader(p).GetInput("file")
            if f:
                files.append(f.Get())
    assert files and all(".usdz[" in a.resolvedPath for a in files)
    assert all(Ar.GetResolver().Resolve(a.resolvedPath) for a in files)
    if lods > 1:  # the variant set stays the portable LOD switch
        lods_prim = stage.GetDefaultPrim().GetChild("LODs")
        assert lods_prim.GetVariantSets().GetVariantSet("LOD").GetVariantNames() == [
            f"LOD{k}" for k in range(lods)
        ]


def test_lod_schemas_only_outside_usdz(textured):
    for fmt in FORMATS:
        stage = Usd.Stage.Open(str(textured[3, fmt][0]))
        lods_prim = stage.GetDefaultPrim().GetChild("LODs")
        has = lods_prim.HasAPI(UsdLod.RootAPI)
        heur = stage.GetDefaultPrim().GetChild("LODHeuristic")
        assert has == bool(heur) == (fmt != "usdz"), fmt


def test_textures_inside_the_usdz(textured):
    """Root layer first (AR Quick Look reads the first entry), then textures/<name>.png with
    the Asset's bytes; no file beside the package."""
    from pxr import Sdf

    tex = synthetic_textures()
    for lods in (1, 3):
        files = textured[lods, "usdz"]
        assert [f.name for f in files] == [f"tree{lods}.usdz"]
        z = Sdf.ZipFile.Open(str(files[0]))
        assert z.GetFileNames() == [
            "synthetic.usdc",
            "textures/bark.png",
            "textures/bark_normal.png",
            "textures/leaf.png",
        ]
        for name, t in tex.items():
            info = z.GetFileInfo(f"textures/{name}.png")
            assert info.size == len(t.png) and info.compressionMethod == 0
            assert info.dataOffset % 64 == 0


@pytest.mark.parametrize("fmt", ["usda", "usdc"])
def test_textures_beside_usda_usdc(textured, fmt):
    """Flat siblings <stem>_<ext>_<name>.png in the same folder, referenced "./<stem>_<ext>_<name>.png"."""
    tex = synthetic_textures()
    files = textured[1, fmt]
    assert [f.name for f in files] == [
        f"tree1.{fmt}",
        f"tree1_{fmt}_bark.png",
        f"tree1_{fmt}_bark_normal.png",
        f"tree1_{fmt}_leaf.png",
    ]
    for name, t in tex.items():
        assert (files[0].parent / f"tree1_{fmt}_{name}.png").read_bytes() == t.png
    stage = Usd.Stage.Open(str(files[0]))
    f = shader(stage, "leaf", "baseTexture").GetInput("file").Get()
    leaf = f"tree1_{fmt}_leaf.png"
    assert f.path == "./" + leaf and f.resolvedPath == str(files[0].parent / leaf)


def side_textures(path) -> dict[str, str]:
    """{file name: SHA-256 of its bytes} of every texture a written .usda/.usdc/.obj refers to beside it (its
    materials' files, and the impostor sidecar's images)."""
    import hashlib
    import json

    if path.suffix == ".obj":
        mtl = (path.parent / (path.stem + ".mtl")).read_text().splitlines()
        names = {ln.split()[-1] for ln in mtl if ln.startswith("map_")}
    else:
        stage = Usd.Stage.Open(str(path))
        names = {
            UsdShade.Shader(p).GetInput("file").Get().path.removeprefix("./")
            for p in stage.Traverse()
            if p.IsA(UsdShade.Shader) and UsdShade.Shader(p).GetShaderId() == "UsdUVTexture"
        }
        sidecar = path.with_name(path.name + ".impostor.json")
        if sidecar.is_file():
            names |= set(json.loads(sidecar.read_text())["images"].values())
    return {n: hashlib.sha256((path.parent / n).read_bytes()).hexdigest() for n in sorted(names)}


def test_outputs_sharing_a_stem_keep_their_own_textures(tmp_path, treegen_cli_run):
    """a.usdc, a.obj and a.usda (three species) in one folder: each names its own side files
    (the extension is in their names), so writing one never overwrites another's textures."""
    outputs = {"a.usdc": "quaking_aspen", "a.obj": "fan_palm", "a.usda": "rush"}
    own = {}
    for name, species in outputs.items():
        proc = treegen_cli_run("make", species, "-o", tmp_path / name, "-q", "--texture-size", "64")
        assert proc.returncode == 0, proc.stderr
        own[name] = side_textures(tmp_path / name)
        assert {n.split("_")[1] for n in own[name]} == {name.split(".")[1]}
        assert len(own[name]) >= 3  # leaf, bark, bark normal (+ the impostor's with EGL)
    leaf = {name: t[name.replace(".", "_") + "_leaf.png"] for name, t in own.items()}
    assert len(set(leaf.values())) == 3  # the species' leaves differ: an overwrite would show
    names = [set(t) for t in own.values()]
    assert not (names[0] & names[1] or names[0] & names[2] or names[1] & names[2])
    for name in outputs:  # after all three were written, each still finds its own bytes
        assert side_textures(tmp_path / name) == own[name], name


@pytest.mark.parametrize("fmt", FORMATS)
def test_leaf_material_cuts_out_by_opacity_threshold(textured, fmt):
    stage = Usd.Stage.Open(str(textured[1, fmt][0]))
    surf = shader(stage, "leaf", "PreviewSurface")
    cutoff = textured_asset().materials[1].alpha_cutoff
    assert surf.GetInput("opacityThreshold").Get() == pytest.approx(cutoff)
    assert source(surf.GetInput("opacity")) == ("baseTexture", "a")
    assert source(surf.GetInput("diffuseColor")) == ("baseTexture", "rgb")
    tex = shader(stage, "leaf", "baseTexture")
    assert tex.GetShaderId() == "UsdUVTexture"
    assert tex.GetInput("sourceColorSpace").Get() == "sRGB"
    assert tex.GetInput("wrapS").Get() == tex.GetInput("wrapT").Get() == "clamp"
    assert source(tex.GetInput("st")) == ("stReader", "result")
    np.testing.assert_allclose(tex.GetInput("scale").Get(), textured_asset().materials[1].base_color)


@pytest.mark.parametrize("fmt", FORMATS)
def test_bark_normal_map_is_raw_and_scaled_to_minus_one_one(textured, fmt):
    stage = Usd.Stage.Open(str(textured[1, fmt][0]))
    surf = shader(stage, "bark", "PreviewSurface")
    assert source(surf.GetInput("normal")) == ("normalTexture", "rgb")
    assert not surf.GetInput("opacityThreshold")  # bark is opaque
    assert not surf.GetInput("opacity").HasConnectedSource()
    n = shader(stage, "bark", "normalTexture")
    assert tuple(n.GetInput("scale").Get()) == (2, 2, 2, 1)
    assert tuple(n.GetInput("bias").Get()) == (-1, -1, -1, 0)
    assert n.GetInput("sourceColorSpace").Get() == "raw"
    assert n.GetInput("wrapS").Get() == n.GetInput("wrapT").Get() == "repeat"
    assert shader(stage, "bark", "baseTexture").GetInput("sourceColorSpace").Get() == "sRGB"


def test_untextured_materials_write_no_files(tmp_path):
    from treegen_cli.exchange import export

    files = export(prepare(synthetic_asset()), tmp_path / "plain.usdc")
    assert [f.name for f in files] == ["plain.usdc"]
    stage = Usd.Stage.Open(str(files[0]))
    assert not [p for p in stage.Traverse() if p.GetName().endswith("Texture")]


def test_texture_names_are_unique_and_shared_once(tmp_path):
    """Two different textures named alike get _1; one texture used twice is written once."""
    from dataclasses import replace

    from treegen_cli.exchange import export

    asset = textured_asset()
    bark, leaf = asset.materials
    other = replace(leaf.base_texture, png=bark.base_texture.png, name="bark")
    asset = replace(
        asset, materials=[bark, replace(leaf, base_texture=other, normal_texture=bark.normal_texture)]
    )
    files = export(prepare(asset), tmp_path / "t.usda")
    assert [f.name for f in files] == [
        "t.usda",
        "t_usda_bark.png",
        "t_usda_bark_1.png",
        "t_usda_bark_normal.png",
    ]
    assert validate_usd(files[0]) == []


def skinned_points(stage, path, code):
    """{mesh name: skinned points at time code `code`} of the SkelRoot at `path`."""
    sq, binding = skel_query(stage, path)
    xforms = sq.ComputeSkinningTransforms(Usd.TimeCode(code))
    out = {}
    for t in binding.GetSkinningTargets():
        pts = Vt.Vec3fArray(UsdGeom.Mesh(t.GetPrim()).GetPointsAttr().Get())
        assert t.ComputeSkinnedPoints(xforms, pts, Usd.TimeCode(code))
        out[t.GetPrim().GetName()] = np.array(pts, np.float64)
    return out


@pytest.mark.parametrize("fmt", FORMATS)
def test_up_axis_y_stands_the_same_tree_up_along_y(tmp_path, fmt):
    """up_axis "y" and "z" write the same tree in metres: Y-up skinned points (rest and
    animated) are the Z-up ones through axes.to_y_up, so the height runs along +Y."""
    import dataclasses as dc

    asset = synthetic_asset(lods=3)
    stages = {}
    for up in ("y", "z"):
        path = tmp_path / f"{up}.{fmt}"
        write_usd(dc.replace(asset, up_axis=up), path)
        assert validate_usd(path) == []
        stages[up] = Usd.Stage.Open(str(path))
        assert UsdGeom.GetStageUpAxis(stages[up]) == up.upper()
        assert UsdGeom.GetStageMetersPerUnit(stages[up]) == 1.0
    y, z = stages["y"], stages["z"]
    for path in lod_paths(z, 3):
        for code in (0.0, 3.0, 4.5):
            py, pz = skinned_points(y, path, code), skinned_points(z, path, code)
            for name in pz:
                np.testing.assert_allclose(py[name], to_y_up(pz[name]), atol=1e-4)
        rest = skinned_points(y, path, 0.0)["bark"]
        assert rest[:, 1].max() > 4.0 and abs(rest[:, 1].min()) < 0.01  # trunk base at 0, up +Y
        lo, hi = np.array(UsdSkel.Root(y.GetPrimAtPath(path)).GetExtentAttr().Get())
        zlo, zhi = np.array(UsdSkel.Root(z.GetPrimAtPath(path)).GetExtentAttr().Get())
        np.testing.assert_allclose(hi - lo, (zhi - zlo)[[0, 2, 1]], atol=1e-6)
    heur = UsdLod.DistanceHeuristic(y.GetPrimAtPath(y.GetDefaultPrim().GetPath().AppendChild("LODHeuristic")))
    if fmt != "usdz":
        zheur = UsdLod.DistanceHeuristic(
            z.GetPrimAtPath(z.GetDefaultPrim().GetPath().AppendChild("LODHeuristic"))
        )
        np.testing.assert_allclose(
            heur.GetCenterAttr().Get(), to_y_up(np.array(zheur.GetCenterAttr().Get())), atol=1e-6
        )


def test_read_drawable_stands_a_y_up_usdz_upright(textured):
    """The preview's reader (Y-up world) sees the same tree from a Y-up .usdz as from a Z-up
    .usdc."""
    from treegen_cli.exchange import read_drawable

    a = read_drawable(textured[1, "usdz"][0])
    b = read_drawable(textured[1, "usdc"][0])
    for pa, pb in zip(a.parts, b.parts):
        np.testing.assert_allclose(pa.positions, pb.positions, atol=1e-5)


def test_bad_up_axis_is_a_user_error(tmp_path):
    import dataclasses as dc

    with pytest.raises(TreegenError, match="up axis"):
        write_usd(dc.replace(synthetic_asset(), up_axis="x"), tmp_path / "t.usdc")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("fmt", FORMATS)
def test_textured_forest_validates(tmp_path, fmt):
    """A forest of textured prototypes: textures named per prototype, written once; a .usdz
    forest is Y up (instances translated by to_y_up(position), turned about +Y) and AR-clean."""
    from treegen_cli.asset import Forest, Instance
    from treegen_cli.exchange import export_forest
    from treegen_cli.prepare import prepare_forest

    proto = textured_asset(lods=3)
    inst = [Instance(0, (3.0, -4.0, 0.5), 30.0, 1.0, lod=k % 3, time_offset=0.1 * k) for k in range(4)]
    forest = prepare_forest(Forest("grove", [proto], inst, loop=2.0))
    files = export_forest(forest, tmp_path / f"grove.{fmt}")
    assert validate_usd(files[0]) == []
    names = [f.name for f in files]
    if fmt == "usdz":
        from pxr import Sdf

        assert names == ["grove.usdz"]
        assert Sdf.ZipFile.Open(str(files[0])).GetFileNames() == [
            "grove.usdc",
            "textures/synthetic_s0_bark.png",
            "textures/synthetic_s0_bark_normal.png",
            "textures/synthetic_s0_leaf.png",
        ]
        if arkit_check.available():
            report = arkit_check.check(files[0])
            assert report["errors"] == [] and report["failed"] == [], report
    else:
        assert names == [
            f"grove.{fmt}",
            f"grove_{fmt}_synthetic_s0_bark.png",
            f"grove_{fmt}_synthetic_s0_bark_normal.png",
            f"grove_{fmt}_synthetic_s0_leaf.png",
        ]
    stage = Usd.Stage.Open(str(files[0]))
    tree = stage.GetPrimAtPath("/grove/Trees/tree0")
    np.testing.assert_allclose(
        tree.GetAttribute("xformOp:translate").Get(), stage_axes(stage, [3.0, -4.0, 0.5])
    )
    up = "Y" if fmt == "usdz" else "Z"
    assert tree.GetAttribute(f"xformOp:rotate{up}").Get() == 30.0
