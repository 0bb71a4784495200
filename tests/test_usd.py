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
from treegen_cli.errors import TreegenError  # noqa: E402
from treegen_cli.exchange.usd import validate_usd, write_usd as _write_usd  # noqa: E402
from treegen_cli.prepare import prepare  # noqa: E402

FORMATS = ("usda", "usdc", "usdz")

def write_usd(asset, path, **opts):
    """Hand-built assets go through the prepare stage, as the pipeline's do."""
    return _write_usd(prepare(asset), path, **opts)



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
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
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
        for j, p in enumerate(joints[1:], 1):   # each joint's parent path is an earlier joint
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
            np.testing.assert_allclose(mesh.GetNormalsAttr().Get(), prim.normals, atol=1e-7)
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
        pts = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(prim.positions))
        assert targets[prim.name].ComputeSkinnedPoints(xforms, pts, Usd.TimeCode(frame))
        assert np.abs(moved - prim.positions).max() > 0.01          # it really moves
        np.testing.assert_allclose(np.array(pts), moved, atol=1e-4)


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
        vis = [UsdGeom.Imageable(stage.GetPrimAtPath(lods_prim.GetPath().AppendChild(n)))
               .ComputeVisibility() for n in items]
        assert vis == [UsdGeom.Tokens.inherited if i == k else UsdGeom.Tokens.invisible
                       for i in range(3)]
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
    calm = dataclasses.replace(lod.clips[0], name="calm", keys=None,
                               rotations=np.repeat(lod.skeleton.rest_rotation[None], 9, 0))
    empty = dataclasses.replace(lod.primitives[1], name="twigs",
                                positions=np.zeros((0, 3), np.float32),
                                normals=np.zeros((0, 3), np.float32), uvs=np.zeros((0, 2), np.float32),
                                indices=np.zeros(0, np.uint32), joints=np.zeros((0, 4), np.uint16),
                                weights=np.zeros((0, 4), np.float32))
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
    with vset.GetVariantEditContext():   # a binding without MaterialBindingAPI, only in LOD1
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
    from treegen_cli.exchange.gltf import quat_to_y_up, read_accessor, read_gltf

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
    usd_anim = UsdSkel.Animation(stage.GetPrimAtPath(
        lod_paths(stage, 1)[0].AppendChild(asset.lods[0].clips[0].name)))
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
    attr = UsdSkel.Animation(stage.GetPrimAtPath(
        lod_paths(stage, 1)[0].AppendChild(clip.name))).GetRotationsAttr()
    samples = np.array([np.array(attr.Get(t)) for t in attr.GetTimeSamples()])
    assert len(samples) == len(clip.times)
    assert (np.einsum("kji,kji->kj", samples[1:], samples[:-1]) > 0).all()


def test_skel_root_extent_holds_every_animated_frame(written):
    asset = synthetic_asset(lods=3)
    stage = Usd.Stage.Open(str(written[3, "usdc"]))
    for path, lod in zip(lod_paths(stage, 3), asset.lods):
        lo, hi = np.array(UsdSkel.Root(stage.GetPrimAtPath(path)).GetExtentAttr().Get())
        sq, binding = skel_query(stage, path)
        for frame in range(len(lod.clips[0].times) * 2 - 1):   # keys and half-way between
            code = frame / 2
            xforms = sq.ComputeSkinningTransforms(Usd.TimeCode(code))
            for target in binding.GetSkinningTargets():
                pts = Vt.Vec3fArray(UsdGeom.Mesh(target.GetPrim()).GetPointsAttr().Get())
                target.ComputeSkinnedPoints(xforms, pts, Usd.TimeCode(code))
                p = np.array(pts)
                assert (p >= lo - 1e-5).all() and (p <= hi + 1e-5).all(), (path, code)
