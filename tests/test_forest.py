"""treegen forest: layout validation, scatter, LOD selection, shared prototype data, writers."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from treegen_cli.cli import cli
from treegen_cli.errors import TreegenError
from treegen_cli.exchange.forest_gltf import build_forest
from treegen_cli.exchange.gltf_container import read_accessor, read_gltf
from treegen_cli.clip import phase_rotate, playback, repeat_clip
from treegen_cli.asset import Forest, Instance
from treegen_cli.exchange import export_forest as write_scene
from treegen_cli.prepare import prepare_forest
from treegen_cli.forest import (
    WindSpec,
    build_scene,
    inside_polygon,
    load_layout,
    parse_layout,
    polygon_area,
    run_forest,
    scatter_points,
    schema_text,
    select_lod,
    time_offsets,
)

from conftest import DASK_ENV, dask_cluster
from synthetic import synthetic_asset

SPECIES = Path(__file__).resolve().parents[1] / "species"
POPLAR, PALM = str(SPECIES / "lombardy_poplar.txt"), str(SPECIES / "palm.txt")
CAMERA = {"position": [0, -40, 2], "target": [0, 0, 5], "fov_deg": 60, "width_px": 1280}
FAST = {"max_joints": 12, "lod_distances": [0, 25, 60]}


def layout_dict(**over) -> dict:
    d = {
        "camera": CAMERA,
        "wind": {"duration": 1.0, "fps": 8, "seed": 3},
        "defaults": FAST,
        "instances": [
            {"species": POPLAR, "position": [0, 0], "seed": 1},
            {"species": PALM, "position": [6, 30, 0.5], "rotation_deg": 90, "scale": 1.5, "seed": 2},
            {"species": POPLAR, "position": [-4, 80], "seed": 1, "scale": 0.8},
        ],
        "scatter": [
            {
                "species": [{"file": POPLAR}, {"file": PALM, "weight": 2}],
                "rectangle": {"min": [-10, -10], "max": [10, 10]},
                "count": 9,
                "min_spacing": 3,
                "seed": 5,
                "variants": 1,
            }
        ],
    }
    d.update(over)
    return d


def write_layout(folder: Path, data: dict, name: str = "layout.json") -> Path:
    p = folder / name
    p.write_text(json.dumps(data))
    return p


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """Built on 2 local worker processes (Dask's local process scheduler)."""
    folder = tmp_path_factory.mktemp("forest")
    layout = load_layout(write_layout(folder, layout_dict()))
    return layout, build_scene(layout, all_lods=False, workers=2, progress=False)


# ----------------------------------------------------------------------------- schema + CLI


def test_schema_is_published_and_printed():
    schema = json.loads(schema_text())
    assert schema["$schema"].endswith("2020-12/schema") and "camera" in schema["properties"]
    assert "camera" not in schema.get("required", [])  # optional since issue 15
    out = CliRunner().invoke(cli, ["forest", "--schema"])
    assert out.exit_code == 0 and json.loads(out.output) == schema


def test_example_layouts_validate():
    examples = Path(__file__).resolve().parents[1] / "examples"
    counts = {p.stem: len(load_layout(p).placements) for p in examples.glob("forest_*.json")}
    assert counts == {"forest_30m": 16, "forest_130m": 16, "forest_1000": 1000}


BAD = [
    ({"camera": None}, "camera: expected an object, got null"),
    ({"camera": {"position": [0, 0, 0]}}, "camera.target: required"),
    ({"camera": {**CAMERA, "fov_deg": 180}}, "camera.fov_deg: 180 is out of range"),
    ({"camera": {**CAMERA, "position": [0, 0]}}, "camera.position: expected 3 items, got 2"),
    (
        {"scatter": [{"species": [], "polygon": [[0, 0], [1, 0], [0, 1]], "count": 1}]},
        "expected at least 1 item, got 0",
    ),
    ({"camera": {**CAMERA, "position": [0, 0, "x"]}}, "camera.position[2]: expected a number"),
    ({"camera": {**CAMERA, "target": CAMERA["position"]}}, "camera.target: must differ"),
    ({"wind": {"speed": -1}}, "wind.speed: -1 is out of range"),
    ({"wind": {"speeed": 1}}, "wind.speeed: unknown key (did you mean speed?); allowed: direction_deg"),
    ({"defaults": {"max_joints": 2.5}}, "defaults.max_joints: 2.5 is not a whole number; allowed [1, 1024]"),
    ({"defaults": {"max_joints": "8"}}, 'defaults.max_joints: expected an integer, got "8"'),
    ({"defaults": {"lod_distances": [0, 30, 30]}}, "defaults.lod_distances: must increase"),
    ({"instances": [], "scatter": []}, "instances: the layout places no trees"),
    ({"instances": [{"species": POPLAR}]}, "instances[0].position: required"),
    (  # a misspelt required key is named as typed (it was "required" alone)
        {"instances": [{"species": POPLAR, "postion": [0, 0]}]},
        'instances[0].position: required (given as "postion": misspelt?)',
    ),
    (  # every count 0 placed no tree and wrote an empty file
        {"instances": [], "scatter": [{**layout_dict()["scatter"][0], "count": 0}]},
        "scatter: the layout places no trees (every scatter's count or density gives 0)",
    ),
    (
        {"instances": [{"species": POPLAR, "position": [0, 0]}, {"species": "nope.txt", "position": [1, 1]}]},
        "instances[1].species: species file 'nope.txt' not found",
    ),
    (
        {"instances": [{"species": POPLAR, "position": [0, 0], "scale": 0}]},
        "instances[0].scale: 0 is out of range",
    ),
    ({"instances": [{"species": POPLAR, "position": [0, 0], "seed": -1}]}, "instances[0].seed: -1"),
    (
        {"scatter": [{"species": [{"file": PALM}], "count": 3}]},
        "scatter[0]: give exactly one of 'rectangle' or 'polygon'",
    ),
    (
        {"scatter": [{"species": [{"file": PALM}], "polygon": [[0, 0], [1, 0], [0, 1]]}]},
        "scatter[0]: give exactly one of 'count' or 'density'",
    ),
    (
        {
            "scatter": [
                {"species": [{"file": PALM, "weight": 0}], "polygon": [[0, 0], [1, 0], [0, 1]], "count": 1}
            ]
        },
        "scatter[0].species[0].weight: 0 is out of range",
    ),
    (
        {"scatter": [{"species": [{"file": "x/y.txt"}], "polygon": [[0, 0], [1, 0], [0, 1]], "count": 1}]},
        "scatter[0].species[0].file: species file 'x/y.txt' not found",
    ),
    (
        {"scatter": [{"species": [{"file": PALM}], "rectangle": {"min": [0, 0], "max": [0, 5]}, "count": 1}]},
        "scatter[0].rectangle.max: must exceed min in x and y, got min [0, 0], max [0, 5]",
    ),
    (  # a bow-tie passed (the schema says simple); one whose lobes cancel read as "zero area"
        {
            "scatter": [
                {"species": [{"file": PALM}], "polygon": [[0, 0], [20, 20], [20, 0], [0, 5]], "count": 1}
            ]
        },
        "scatter[0].polygon: edges 0-1 and 2-3 cross; give a simple polygon",
    ),
    (  # 100,000 trees on 20 × 20 m passed and took 13 GB to write
        {
            "scatter": [
                {"species": [{"file": PALM}], "rectangle": {"min": [0, 0], "max": [2, 2]}, "count": 41}
            ]
        },
        "scatter[0].count: 41 trees on 4 m² is 10.25 per m²; allowed at most 10 per m² (as 'density')",
    ),
    (
        {"scatter": [{"species": [{"file": PALM}], "polygon": [[0, 0], [1, 1], [2, 2]], "count": 1}]},
        "scatter[0].polygon: has zero area",
    ),
    (
        {
            "scatter": [
                {
                    "species": [{"file": PALM}],
                    "rectangle": {"min": [0, 0], "max": [10, 10]},
                    "count": 500,
                    "min_spacing": 2,
                }
            ]
        },
        "scatter[0]: impossible scatter: 500 trees",
    ),
    (
        {
            "scatter": [
                {
                    "species": [{"file": PALM}],
                    "rectangle": {"min": [0, 0], "max": [10, 10]},
                    "count": 2,
                    "scale": [2, 1],
                }
            ]
        },
        "scatter[0].scale: [low, high]",
    ),
    ({"extra": 1}, "extra: unknown key; allowed:"),
    (
        {"instances": [{"species": POPLAR, "position": [0, 0], "sede": 1}]},
        "instances[0].sede: unknown key (did you mean seed?)",
    ),
]


@pytest.mark.parametrize("change, message", BAD, ids=[m.split(":")[0] for _, m in BAD])
def test_bad_layouts_name_the_json_path(tmp_path, change, message):
    data = layout_dict(**change)
    with pytest.raises(TreegenError) as e:
        parse_layout(data, tmp_path / "layout.json")
    assert message in str(e.value)


def test_a_species_over_the_layouts_size_bound_names_the_layout_key(tmp_path):
    """defaults.max_size is the bound a prototype's size refusal tells to raise (it said
    `--max-size`, a flag `treegen forest` does not have)."""
    from treegen_cli.forest.options import make_options
    from treegen_cli.generate import generate
    from treegen_cli.params import load_params

    data = layout_dict(scatter=[], instances=[{"species": PALM, "position": [0, 0]}])
    data["defaults"] = {**FAST, "max_size": 5}
    options = make_options(load_layout(write_layout(tmp_path, data)))
    with pytest.raises(
        TreegenError, match=r"over the plausibility bound of 5 m; .*raise the bound with defaults\.max_size$"
    ):
        generate(load_params(PALM), 0, options.generate)


def test_bad_json_and_nan(tmp_path):
    p = tmp_path / "l.json"
    p.write_text('{"camera": ')
    with pytest.raises(TreegenError, match=r"l.json: line 1 column \d+: invalid JSON"):
        load_layout(p)
    p.write_text(json.dumps(layout_dict()).replace('"fov_deg": 60', '"fov_deg": NaN'))
    with pytest.raises(TreegenError, match=r"camera.fov_deg: expected a number \(finite\), got NaN"):
        load_layout(p)
    p.write_text(json.dumps(layout_dict()).replace('"seed": 3', '"seed": 3, "seed": 4'))
    with pytest.raises(TreegenError, match=r'l.json: key "seed" appears twice in one object'):
        load_layout(p)  # (json keeps the last silently)


def test_cli_bad_layout_exits_2_and_writes_nothing(tmp_path):
    import subprocess
    import sys

    layout = write_layout(tmp_path, layout_dict(instances=[{"species": "missing.txt", "position": [0, 0]}]))
    out = tmp_path / "forest.glb"
    proc = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys; from treegen_cli.cli import main; main(sys.argv[1:])",
            "forest",
            str(layout),
            "-o",
            str(out),
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2
    assert "instances[0].species: species file 'missing.txt' not found" in proc.stderr
    assert "Traceback" not in proc.stderr
    assert list(tmp_path.iterdir()) == [layout]


def test_species_paths_are_relative_to_the_layout(tmp_path):
    sub = tmp_path / "scenes"
    sub.mkdir()
    rel = str(Path("..") / "species" / "palm.txt")
    (tmp_path / "species").mkdir()
    (tmp_path / "species" / "palm.txt").write_text(Path(PALM).read_text())
    layout = load_layout(
        write_layout(sub, layout_dict(instances=[{"species": rel, "position": [1, 2]}], scatter=[]))
    )
    assert layout.placements[0].species == (tmp_path / "species" / "palm.txt").resolve()


# ----------------------------------------------------------------------------- scatter


def test_scatter_rectangle_bounds_and_spacing():
    rect = np.array([[-5.0, 0.0], [15.0, 0.0], [15.0, 8.0], [-5.0, 8.0]])
    for seed in range(5):
        pts = scatter_points(rect, False, 40, 1.5, np.random.default_rng(seed))
        assert pts.shape == (40, 2)
        assert np.all(pts >= [-5, 0]) and np.all(pts <= [15, 8])
        assert cKDTree(pts).query(pts, k=2)[0][:, 1].min() >= 1.5


def test_scatter_polygon_bounds_and_spacing():
    star = np.array(
        [
            [np.cos(a) * r, np.sin(a) * r]
            for a, r in zip(np.linspace(0, 2 * np.pi, 10, endpoint=False), [20, 8] * 5)
        ]
    )
    pts = scatter_points(star, True, 60, 2.0, np.random.default_rng(1))
    assert len(pts) == 60 and inside_polygon(pts, star).all()
    assert cKDTree(pts).query(pts, k=2)[0][:, 1].min() >= 2.0
    # the point-in-polygon test agrees with the area: a unit square's inside fraction
    sq = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    assert polygon_area(sq) == 1.0
    probe = np.random.default_rng(0).uniform(-1, 2, (20000, 2))
    assert abs(inside_polygon(probe, sq).mean() - 1 / 9) < 0.01


def test_an_instance_scaled_past_max_size_is_refused_by_its_place(tmp_path):
    """A scale of 100 on the palm built a 2.5 km tree (make refuses anything over 150 m): the
    biggest offender is named by its place in the layout before anything is written; the
    layout's defaults.max_size raises the bound on purpose."""
    data = layout_dict(
        instances=[
            {"species": PALM, "position": [0, 0]},
            {"species": PALM, "position": [9, 0], "scale": 100},
        ],
        camera=None,
    )
    data.pop("camera")
    layout = load_layout(write_layout(tmp_path, data))
    with pytest.raises(TreegenError, match=r"instances\[1\]: scale 100 makes palm [\d,.]+ m across "):
        build_scene(layout, workers=1, progress=False)
    data["defaults"] = {**FAST, "max_size": 5000}
    sc = build_scene(load_layout(write_layout(tmp_path, data)), workers=1, progress=False)
    assert max(i.scale for i in sc.instances) == 100.0


def test_density_sets_the_count(tmp_path):
    data = layout_dict(
        instances=[],
        scatter=[
            {
                "species": [{"file": PALM}],
                "rectangle": {"min": [0, 0], "max": [20, 10]},
                "density": 0.05,
                "seed": 2,
            }
        ],
    )
    layout = parse_layout(data, tmp_path / "l.json")
    assert len(layout.placements) == 10  # 0.05 / m² × 200 m²
    pos = np.array([p.position for p in layout.placements])
    assert np.all((pos[:, :2] >= 0) & (pos[:, :2] <= [20, 10]))


# ----------------------------------------------------------------------------- LOD + phase


def test_select_lod_by_distance_over_scale():
    starts = [0.0, 10.0, 30.0, 130.0]
    d = np.array([0.0, 9.9, 10.0, 29.0, 31.0, 500.0])
    assert select_lod(d, starts).tolist() == [0, 0, 1, 1, 2, 3]
    assert select_lod([20.0], starts, scale=2.0).tolist() == [1]  # 2× tree at 20 m ≈ 10 m
    assert select_lod([50.0, 5.0], [0.0]).tolist() == [0, 0]  # single LOD: always LOD0


def test_nearer_instances_get_finer_lods(scene):
    _, sc = scene
    eff = np.array([i.distance / i.scale for i in sc.instances])
    lod = np.array([i.lod for i in sc.instances])
    order = np.argsort(eff)
    assert np.all(np.diff(lod[order]) >= 0)
    assert lod.min() < lod.max()  # the layout spans LODs
    for i in sc.instances:
        starts = [lod.distance for lod in sc.prototypes[i.prototype].lods]
        assert starts[i.lod] <= i.distance / i.scale


def test_time_offsets_follow_the_wind_and_wrap():
    wind = WindSpec(speed=5.0, direction_deg=0.0, duration=4.0, phase_jitter=0.0)
    pos = np.array([[0.0, 0, 0], [5.0, 0, 0], [10.0, 3, 0], [25.0, 0, 0]])
    assert np.allclose(time_offsets(pos, wind), [0.0, 1.0, 2.0, 1.0])  # 25 m: 5 s wraps to 1
    jit = time_offsets(pos, replace(wind, phase_jitter=0.5))
    assert np.all((jit >= 0) & (jit < 4.0)) and not np.allclose(jit, [0, 1, 2, 1])


def test_phase_rotate_plays_the_shifted_clip_exactly():
    clip = synthetic_asset(1).lods[0].clips[0]  # sparse keys
    assert clip.keys is not None
    n = len(clip.times) - 1
    base = playback(clip)
    for shift in range(1, n):
        rot = phase_rotate(clip, shift)
        want = np.concatenate([np.roll(base[:n], -shift, axis=0), np.roll(base[:n], -shift, axis=0)[:1]])
        got = playback(rot)
        assert np.allclose(np.abs(np.sum(got * want, axis=-1)), 1.0, atol=1e-9)
        assert all(k[0] == 0 and k[-1] == n for k in rot.keys)
    twice = repeat_clip(clip, 2)
    assert len(twice.times) == 2 * n + 1 and np.isclose(twice.times[-1], 2 * clip.times[-1])
    assert np.allclose(playback(twice)[n:], base)


# ----------------------------------------------------------------------------- built scene


def test_instances_and_placement_match_the_layout(scene, tmp_path):
    layout, sc = scene
    assert len(sc.instances) == 3 + 9
    keys = {(p.species, p.seed) for p in layout.placements}
    assert len(sc.prototypes) == len(keys)  # each (species, seed) once
    path = tmp_path / "f.glb"
    write_scene(sc, path)
    gltf, blob = read_gltf(path)
    nodes = gltf["nodes"]
    roots = gltf["scenes"][0]["nodes"]
    # per tree, its skinned mesh and its placed rig side by side at the root
    meshes = [r for r in roots if "mesh" in nodes[r]]
    places = [r for r in roots if "mesh" not in nodes[r]]
    assert len(meshes) == len(places) == len(layout.placements)
    assert all("children" not in nodes[m] for m in meshes)
    for m, pl in zip(meshes, places):
        assert nodes[pl]["name"] == nodes[m]["name"] + "_place"
        assert gltf["skins"][nodes[m]["skin"]]["skeleton"] == nodes[pl]["children"][0]
    for root, p in zip(places, layout.placements):
        place = nodes[root]
        x, y, z = p.position
        assert np.allclose(place.get("translation", [0, 0, 0]), [x, z, -y], atol=1e-6)  # Y up
        q = place.get("rotation", [0, 0, 0, 1])
        assert np.allclose(
            Rotation.from_quat(q).as_rotvec(),
            [0, np.radians((p.rotation_deg + 180) % 360 - 180), 0],
            atol=1e-6,
        )
        assert np.allclose(place.get("scale", [1, 1, 1]), [p.scale] * 3)
    # placed joints: each instance's skin uses its own joint nodes, never another's
    joint_sets = [set(s["joints"]) for s in gltf["skins"]]
    assert sum(len(s) for s in joint_sets) == len(set().union(*joint_sets))


def test_shared_data_is_not_duplicated(scene):
    _, sc = scene
    protos = sc.prototypes[:3]

    def blob_size(n):
        rng = np.random.default_rng(n)
        inst = [
            Instance(i % 3, (float(x), float(y), 0.0), float(r), 1.0, 0, float(t), variant=i % 4)
            for i, (x, y, r, t) in enumerate(
                zip(
                    rng.uniform(-50, 50, n),
                    rng.uniform(-50, 50, n),
                    rng.uniform(0, 360, n),
                    rng.uniform(0, 1, n),
                )
            )
        ]
        s = prepare_forest(Forest("t", protos, inst, phase_variants=4, loop=1.0))
        gltf, blob = build_forest(s)
        assert len(gltf["meshes"]) == 3 and len({sk["inverseBindMatrices"] for sk in gltf["skins"]}) == 3
        return len(blob)

    small, big = blob_size(10), blob_size(100)
    assert big <= 1.5 * small


def test_gltf_forest_validator_clean(scene, tmp_path):
    from treegen_cli.exchange.validate import ValidatorUnavailable, summary, validate_gltf

    _, sc = scene
    for all_lods in (False, True):
        path = tmp_path / f"f{int(all_lods)}.glb"
        write_scene(prepare_forest(replace(sc, all_lods=all_lods)), path)
        try:
            report = validate_gltf(path)
        except ValidatorUnavailable as e:
            pytest.skip(str(e))
        assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0, summary(report)
        gltf, _ = read_gltf(path)
        names = [m["name"] for m in gltf["materials"]]  # each species has a "bark", a "leaf"…
        assert len(set(names)) == len(names) and all("_s" in n for n in names), names
        if all_lods:
            lod_ids = [
                gltf["nodes"][r]["extensions"]["MSFT_lod"]["ids"]
                for r in gltf["scenes"][0]["nodes"]
                if "mesh" in gltf["nodes"][r]
            ]
            assert all(len(ids) == len(sc.prototypes[0].lods) - 1 for ids in lod_ids)
            assert gltf["extensionsUsed"] == ["MSFT_lod"]


def test_gltf_phase_variants_share_samplers(scene, tmp_path):
    _, sc = scene
    gltf, blob = build_forest(sc)
    anim = gltf["animations"][0]
    targets = [(c["target"]["node"], c["target"]["path"]) for c in anim["channels"]]
    assert len(targets) == len(set(targets))
    assert len(anim["samplers"]) < len(anim["channels"])  # shared across instances
    # channel rotations are unit quaternions
    q = read_accessor(gltf, blob, anim["samplers"][0]["output"])
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)


def test_usd_forest_validator_clean_and_offsets(scene, tmp_path):
    from pxr import Usd

    from treegen_cli.exchange.validate import validate_usd

    _, sc = scene
    path = tmp_path / "f.usda"
    write_scene(sc, path)
    assert validate_usd(path) == []
    stage = Usd.Stage.Open(str(path))
    trees = stage.GetPrimAtPath(f"/{sc.name}/Trees").GetChildren()
    assert len(trees) == len(sc.instances) and all(t.IsInstance() for t in trees)
    text = path.read_text()
    n_protos = text.count("def SkelAnimation")
    assert n_protos == len({(i.prototype, i.lod) for i in sc.instances})  # prototypes once
    fps = stage.GetTimeCodesPerSecond()
    for prim, inst in zip(trees, sc.instances):
        tr = prim.GetAttribute("xformOp:translate").Get()
        assert np.allclose(tr, inst.position)
        anim = next(
            p
            for p in Usd.PrimRange(prim, Usd.TraverseInstanceProxies())
            if p.GetTypeName() == "SkelAnimation"
        )
        samples = anim.GetAttribute("rotations").GetTimeSamples()
        offset = round(inst.time_offset * fps) % round(sc.loop * fps)
        assert samples[0] == -offset  # its own phase, no new data


def test_a_still_forest_has_its_wind_loop(tmp_path):
    """Wind speed 0: each tree's LODs get a still root track in `wind_loop`, as a single tree's
    file does, so engines that play it by name find it (the forest had no animation)."""
    from treegen_cli.exchange.gltf_container import read_gltf

    wind = {"speed": 0.0, "duration": 1.0, "fps": 8, "seed": 3}
    layout = write_layout(
        tmp_path, layout_dict(scatter=[], wind=wind, defaults={**FAST, "lod_distances": [0]})
    )
    run_forest(layout, tmp_path / "f.glb", all_lods=False, workers=1, progress=False)
    gltf, _ = read_gltf(tmp_path / "f.glb")
    (anim,) = gltf["animations"]
    roots = sorted(s["joints"][0] for s in gltf["skins"])
    assert anim["name"] == "wind_loop" and sorted(c["target"]["node"] for c in anim["channels"]) == roots


def test_run_forest_summary(tmp_path):
    layout = write_layout(tmp_path, layout_dict(scatter=[], defaults={**FAST, "lod_distances": [0]}))
    s = run_forest(layout, tmp_path / "f.usdz", all_lods=False, workers=1, progress=False)
    assert s["instances"] == 3 and s["prototypes"] == 2 and s["instances_per_lod"] == {"lod0": 3}
    assert s["bytes"] == (tmp_path / "f.usdz").stat().st_size
    # a single LOD at distance 0 keeps the dense clip: the CPU method updates every leaf vertex
    assert s["leaf_vertex_updates_per_frame"] == s["leaf_vertex_updates_per_frame_without_lod"] > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["f.usdz", "layout.json"]


def test_oversized_forest_is_refused_naming_the_flag(tmp_path):
    """A layout over --max-trees is refused before anything is built or written."""
    import json as _json
    import subprocess
    import sys

    species = Path(__file__).resolve().parent.parent / "species" / "palm.txt"
    layout = {
        "camera": {"position": [0, -30, 2], "target": [0, 0, 2]},
        "scatter": [
            {
                "species": [{"file": str(species)}],
                "rectangle": {"min": [-50, -50], "max": [50, 50]},
                "count": 300,
            }
        ],
    }
    path = tmp_path / "big.json"
    path.write_text(_json.dumps(layout))
    out = tmp_path / "f.glb"
    proc = subprocess.run(
        [sys.executable, "-m", "treegen_cli", "forest", str(path), "-o", str(out), "--max-trees", "100"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2, proc.stderr
    assert "--max-trees" in proc.stderr and "scatter[0]" in proc.stderr
    assert "Traceback" not in proc.stderr and not out.exists()
    # the limit named is the one typed, the count as given, the instances before counted
    layout["instances"] = [{"species": str(species), "position": [0, 0]}] * 3
    layout["scatter"][0]["count"] = 10
    path.write_text(_json.dumps(layout))
    proc = subprocess.run(
        [sys.executable, "-m", "treegen_cli", "forest", str(path), "-o", str(out), "--max-trees", "5"],
        capture_output=True,
        text=True,
    )
    assert "scatter[0]: 10 trees (count) and 3 placed before, over the limit of 5 trees" in proc.stderr


# ----------------------------------------------------------------------------- on Dask


def test_dask_prototypes_equal_the_in_process_build_byte_for_byte(scene, tmp_path):
    """The `scene` fixture built its prototypes on 2 local worker processes; built in this
    process instead, every writer gives the same bytes."""
    layout, on_dask = scene
    here = build_scene(layout, all_lods=False, workers=1, progress=False)
    assert (on_dask.cluster, here.cluster) == ("2 local worker(s)", "this process")
    (tmp_path / "dask").mkdir()
    (tmp_path / "here").mkdir()
    for suffix in (".glb", ".usda"):  # (.usda: texture files are named after the stem)
        a, b = tmp_path / "dask" / f"f{suffix}", tmp_path / "here" / f"f{suffix}"
        write_scene(on_dask, a)
        write_scene(here, b)
        assert a.read_bytes() == b.read_bytes(), suffix


def test_local_workers_are_forks_of_a_threadless_client_and_run_tasks_in_order(tmp_path):
    """executor.process_pool: a client with one thread and no OpenGL (the forest command's)
    forks its workers, which inherit what it holds; with another thread running they come
    from the fork server instead. Either way the tasks start in list order, one a worker at
    a time (the long first one holds its worker, the other takes every other task in turn),
    results come back in list order, done(i) is called once per task, a task's TreegenError
    is raised in the client as it was raised, a worker that dies is reported in one line, a
    Ctrl-C stops the running tasks, and no worker process is left."""
    import os
    import subprocess
    import sys

    # the tasks live in a module: the fork server's workers import them (as build_prototype)
    (tmp_path / "jobs.py").write_text("""
import os, time
from treegen_cli.errors import TreegenError
held = []
def job(seconds):
    start = time.monotonic()
    time.sleep(seconds)
    return os.getpid(), os.getppid(), start, len(held)
def fails():
    raise TreegenError("species/x.txt:3: shape 9 is not in 0-8")
def dies():
    os.kill(os.getpid(), 9)
""")
    code = """
import json, os, threading, time
import psutil
import signal
from jobs import dies, fails, held, job
from treegen_cli.errors import TreegenError
from treegen_cli.executor import can_fork, process_pool
def run():
    safe = can_fork()
    done = []
    with process_pool(2) as (run, where):
        out = run([(job, s) for s in (1.5, 0.05, 0.05, 0.05, 0.05)], done=done.append)
        try:
            run([(job, 0.0), (fails,)])
            error = None
        except TreegenError as e:
            error = str(e)
    return safe, out, sorted(done), error, where
def interrupted():
    def ctrl_c(*_):
        raise KeyboardInterrupt
    signal.signal(signal.SIGALRM, ctrl_c)
    start = time.monotonic()
    try:
        with process_pool(2) as (run, where):
            signal.alarm(1)
            run([(job, 60.0)] * 3)
    except KeyboardInterrupt:
        return time.monotonic() - start
def died():
    try:
        with process_pool(2) as (run, where):
            run([(job, 0.5), (dies,), (job, 0.1)])
    except TreegenError as e:
        return str(e)
held.append(1)
first = run()
stopped, crashed = interrupted(), died()
threading.Thread(target=time.sleep, args=(600,), daemon=True).start()
second = run()
helpers = ('multiprocessing.forkserver', 'multiprocessing.resource_tracker')
kids = [p for p in psutil.Process().children(recursive=True) if not any(h in ' '.join(p.cmdline()) for h in helpers)]
print(json.dumps([os.getpid(), first, second, stopped, crashed, len(kids)]))
"""
    env = {**DASK_ENV, "PYTHONPATH": f"{tmp_path}{os.pathsep}{DASK_ENV.get('PYTHONPATH', '')}"}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert proc.returncode == 0, proc.stderr
    pid, first, second, stopped, crashed, kids = json.loads(proc.stdout.strip().splitlines()[-1])
    assert stopped < 30  # Ctrl-C stops the workers' 60 s tasks instead of waiting for them
    assert crashed.startswith("a worker process died while building"), crashed
    for (safe, out, done, error, where), forked in ((first, True), (second, False)):
        assert safe is forked and where == "2 local worker(s)"
        assert [p == pid for _w, p, _s, _h in out] == [forked] * 5
        assert [h for _w, _p, _s, h in out] == [int(forked)] * 5  # inherited only when forked
        long, *short = out
        assert long[0] not in [w for w, _p, _s, _h in short]  # the long task's worker ran nothing else
        assert [s for _w, _p, s, _h in short] == sorted(s for _w, _p, s, _h in short)
        assert done == [0, 1, 2, 3, 4]
        assert error == "species/x.txt:3: shape 9 is not in 0-8"
    assert kids == 0  # no worker left behind (the fork server's helpers stay, as multiprocessing's do)


def test_local_workers_exit_when_their_parent_is_killed(tmp_path):
    """A forest killed outright (SIGKILL: a CI job cancelled, `timeout -s KILL`) leaves no
    worker building on as an orphan: each watches its parent and exits once it is gone."""
    import os
    import signal
    import subprocess
    import sys
    import time

    import psutil

    (tmp_path / "napjobs.py").write_text(
        "import os, time\ndef nap(s):\n    time.sleep(s)\n    return os.getpid()\n"
    )
    code = """
import sys
from napjobs import nap
from treegen_cli.executor import process_pool
with process_pool(2) as (run, where):
    print(*sorted(set(run([(nap, 0.3), (nap, 0.3)]))), flush=True)
    run([(nap, 120.0), (nap, 120.0)])
"""
    env = {**DASK_ENV, "PYTHONPATH": f"{tmp_path}{os.pathsep}{DASK_ENV.get('PYTHONPATH', '')}"}
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True, env=env)
    workers = [int(x) for x in proc.stdout.readline().split()]
    assert len(workers) == 2, workers
    time.sleep(0.5)  # both are in their 120 s naps
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline and any(psutil.pid_exists(w) for w in workers):
        time.sleep(0.2)
    alive = [
        w for w in workers if psutil.pid_exists(w) and psutil.Process(w).status() != psutil.STATUS_ZOMBIE
    ]
    for w in alive:  # (do not leave them behind if the test fails)
        os.kill(w, signal.SIGKILL)
    assert alive == []


def test_embedded_cluster_gives_a_worker_its_next_task_only_when_it_is_free():
    """A worker of the embedded cluster holds one task at a time (executor.QUIET's
    worker-saturation): the one running a long task is given no other, so at the end no worker
    idles while another still has work queued behind a long one. Dask's default (1.1 × 1
    thread → 2 slots) queued the third task behind the first on its worker here. Dask queues
    a group of more than twice the threads sent in one go (client.map, as the forest's)."""
    import subprocess
    import sys

    code = """
import json, time
from treegen_cli.executor import dask_client, worker_name
def job(seconds):
    start = time.monotonic()
    time.sleep(seconds)
    return worker_name(), start
with dask_client(None, 2) as (client, where):
    client.wait_for_workers(2, timeout=60)
    seconds = (3.0,) + (0.05,) * 5
    futures = client.map(job, seconds, key=[f"treegen-test-{k}" for k in range(len(seconds))])
    print(json.dumps([f.result() for f in futures]))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=DASK_ENV)
    assert proc.returncode == 0, proc.stderr
    ran = json.loads(proc.stdout.strip().splitlines()[-1])
    workers = [w for w, _start in ran]
    assert workers[0] not in workers[1:], ran  # the long task's worker ran nothing else
    assert len(set(workers[1:])) == 1, ran
    starts = [start for _w, start in ran[1:]]
    assert starts == sorted(starts), ran  # none held back behind the long one, then run last


@pytest.fixture(scope="module")
def dask_scheduler():
    """A real `dask scheduler` and one `dask worker` (this checkout's treegen_cli)."""
    with dask_cluster() as (address, _workers):
        yield address, DASK_ENV


def test_forest_on_a_dask_scheduler_writes_the_in_process_bytes(dask_scheduler, tmp_path):
    """`treegen forest --scheduler ADDRESS` (and DASK_SCHEDULER_ADDRESS) builds the
    prototypes on that cluster's workers; the file is the one a one-process run writes."""
    import subprocess
    import sys

    address, env = dask_scheduler
    layout = write_layout(tmp_path, layout_dict(scatter=[]))
    (tmp_path / "remote").mkdir()
    (tmp_path / "here").mkdir()
    for suffix, args, extra_env in (
        (".glb", ["--scheduler", address], {}),
        (".usda", [], {"DASK_SCHEDULER_ADDRESS": address}),
    ):
        remote, here = tmp_path / "remote" / f"f{suffix}", tmp_path / "here" / f"f{suffix}"
        proc = subprocess.run(
            [sys.executable, "-m", "treegen_cli", "forest", str(layout), "-o", str(remote), *args, "--json"],
            capture_output=True,
            text=True,
            env={**env, **extra_env},
        )
        assert proc.returncode == 0, proc.stderr
        s = json.loads(proc.stdout)
        assert s["prototypes"] == 2 and s["cluster"] == f"1 worker(s) at {address}"
        run_forest(layout, here, workers=1, progress=False)
        assert remote.read_bytes() == here.read_bytes(), suffix
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "treegen_cli",
            "forest",
            str(layout),
            "-o",
            str(tmp_path / "x.glb"),
            "--scheduler",
            address,
            "--workers",
            "2",
        ],
        capture_output=True,
        text=True,
        env=env,
    )
    assert proc.returncode == 2 and "--workers 2: only for workers on this machine" in proc.stderr


def test_same_named_species_files_are_two_prototypes_on_a_scheduler(dask_scheduler, tmp_path):
    """a/tree.txt and b/tree.txt with one seed are two prototypes (Dask keys carry the index:
    by name and seed alone both tasks were one, and one tree was built for both)."""
    import shutil

    address, env = dask_scheduler
    for folder, src in (("a", POPLAR), ("b", PALM)):
        (tmp_path / folder).mkdir()
        shutil.copy(src, tmp_path / folder / "tree.txt")
    data = layout_dict(
        instances=[
            {"species": f"{f}/tree.txt", "position": [x, 0], "seed": 1} for f, x in (("a", 0), ("b", 8))
        ],
        scatter=[],
    )
    layout = load_layout(write_layout(tmp_path, data))
    remote = build_scene(layout, all_lods=False, progress=False, scheduler=address)
    here = build_scene(layout, all_lods=False, workers=1, progress=False)
    assert [a.name for a in remote.prototypes] == [a.name for a in here.prototypes]
    assert len({a.name for a in here.prototypes}) == 2
    write_scene(remote, tmp_path / "remote.glb")
    write_scene(here, tmp_path / "here.glb")
    assert (tmp_path / "remote.glb").read_bytes() == (tmp_path / "here.glb").read_bytes()


# ----------------------------------------------------------------------------- a forest to walk through


def no_camera(**over) -> dict:
    d = layout_dict(**over)
    del d["camera"]
    return d


@pytest.fixture(scope="module")
def walk(tmp_path_factory):
    """The default forest: no camera, every tree with all its LODs, as .glb and .usda."""
    folder = tmp_path_factory.mktemp("walk")
    layout = load_layout(write_layout(folder, no_camera(scatter=[])))
    sc = build_scene(layout, workers=1, progress=False)
    files = {s: folder / f"walk{s}" for s in (".glb", ".usda")}
    for path in files.values():
        write_scene(sc, path)
    return layout, sc, files


def test_default_forest_needs_no_camera_and_carries_every_lod(walk):
    layout, sc, _ = walk
    assert layout.camera is None and sc.all_lods
    assert [i.source for i in sc.instances] == [p.source for p in layout.placements]  # layout order
    assert {i.lod for i in sc.instances} == {0}
    # each prototype ends in its impostor, as `treegen make` builds it (--no-impostor: not)
    for a in sc.prototypes:
        *geo, imp = a.lods
        assert len(geo) == len(FAST["lod_distances"]) and imp.impostor is not None
        assert all(lod.impostor is None for lod in geo) and imp.distance >= 1.5 * geo[-1].distance
        assert sum(len(p.indices) for p in imp.primitives) == 3 * 8
        mat = next(m for m in a.materials if m.name == "impostor")  # the cards' strip, normal-mapped
        assert mat.base_texture.name == "impostor_cards" and mat.normal_texture is not None
    from treegen_cli.forest.build import make_options

    assert make_options(layout).impostor is not None and make_options(layout, impostor=False).impostor is None
    with pytest.raises(TreegenError, match=r"--camera-lod: .* has no camera"):
        build_scene(layout, all_lods=False, workers=1, progress=False)


def test_gltf_instance_references_every_shared_lod_mesh_skin_and_clip(walk):
    from treegen_cli.exchange import read_drawable

    _, sc, files = walk
    gltf, _blob = read_gltf(files[".glb"])
    nodes, skins = gltf["nodes"], gltf["skins"]
    n_lods = [len(a.lods) for a in sc.prototypes]
    assert len(gltf["meshes"]) == sum(n_lods)  # prototypes × LODs, shared
    roots = [r for r in gltf["scenes"][0]["nodes"] if "mesh" in nodes[r]]
    assert len(roots) == len(sc.instances)
    driven = {c["target"]["node"] for c in gltf["animations"][0]["channels"]}
    meshes_of: dict[int, list[int]] = {}
    for r, inst in zip(roots, sc.instances):
        ids = nodes[r]["extensions"]["MSFT_lod"]["ids"]
        lods = [r, *ids]
        assert len(lods) == n_lods[inst.prototype] > 1  # every LOD, on every tree
        meshes = [nodes[n]["mesh"] for n in lods]
        assert meshes_of.setdefault(inst.prototype, meshes) == meshes  # the prototype's meshes
        for k, n in enumerate(lods):  # each LOD: its own rig, placed like the tree, animated
            joints = skins[nodes[n]["skin"]]["joints"]
            assert len(joints) == len(sc.prototypes[inst.prototype].lods[k].skeleton.names)
            place = next(p for p in nodes if skins[nodes[n]["skin"]]["skeleton"] in p.get("children", []))
            assert place["name"] == f"{nodes[n]['name']}_place"
            assert np.allclose(
                place.get("translation", [0, 0, 0]), [inst.position[0], inst.position[2], -inst.position[1]]
            )
            assert driven & set(joints) or k == n_lods[inst.prototype] - 1
            # a tree's switches scale with it: the same size on screen (the palm at 1.5 ×)
            d = sc.prototypes[inst.prototype].lods[k].distance * inst.scale
            assert nodes[n]["extras"]["treegen_lod"]["distance_m"] == pytest.approx(d, rel=1e-12)
    # the project's reader follows the first tree's MSFT_lod chain: exactly its prototype's LODs
    first = sc.prototypes[sc.instances[0].prototype]
    for k, lod in enumerate(first.lods):
        d = read_drawable(files[".glb"], lod=k)
        assert sum(len(p.positions) for p in d.parts) == sum(len(q.positions) for q in lod.primitives)
    with pytest.raises(TreegenError, match=f"LODs 0..{len(first.lods) - 1}"):
        read_drawable(files[".glb"], lod=len(first.lods))


def test_usd_instance_has_the_lod_variant_set_and_stays_instanced(walk):
    from pxr import Usd, UsdGeom

    from treegen_cli.exchange.validate import validate_usd

    _, sc, files = walk
    assert validate_usd(files[".usda"]) == []  # under every variant, too
    stage = Usd.Stage.Open(str(files[".usda"]))
    protos = stage.GetPrimAtPath(f"/{sc.name}/Prototypes").GetAllChildren()
    assert len(protos) == len(sc.prototypes)  # one prim per prototype
    trees = stage.GetPrimAtPath(f"/{sc.name}/Trees").GetChildren()

    def shown(tree):
        return [
            p.GetName()
            for p in Usd.PrimRange(tree, Usd.TraverseInstanceProxies())
            if p.GetParent().GetName() == "LODs"
            and UsdGeom.Imageable(p).ComputeVisibility() != UsdGeom.Tokens.invisible
        ]

    for tree, inst in zip(trees, sc.instances):
        vset = tree.GetVariantSets().GetVariantSet("LOD")
        names = [f"LOD{k}" for k in range(len(sc.prototypes[inst.prototype].lods))]
        assert tree.IsInstance() and vset.GetVariantNames() == names
        assert vset.GetVariantSelection() == "LOD0" and shown(tree) == ["LOD0"]
        skel_roots = [
            p for p in Usd.PrimRange(tree, Usd.TraverseInstanceProxies()) if p.GetTypeName() == "SkelRoot"
        ]
        assert len(skel_roots) == len(names)  # every LOD is in the tree
    # an engine switches one tree; it stays an instance and the others keep theirs
    last = trees[-1]
    last.GetVariantSets().GetVariantSet("LOD").SetVariantSelection("LOD2")
    assert last.IsInstance() and shown(last) == ["LOD2"] and shown(trees[0]) == ["LOD0"]


def test_walk_forest_is_validator_clean_and_loads_in_godot_and_three(walk):
    """Godot 3.2 (headless editor import + inspect) and three.js take the all-LOD forest: a
    skeleton per tree and LOD with its bones bound by name, every track resolved."""
    import clients
    from treegen_cli.exchange.validate import ValidatorUnavailable, summary, validate_gltf

    _, sc, files = walk
    try:
        report = validate_gltf(files[".glb"])
    except ValidatorUnavailable as e:
        pytest.skip(str(e))
    assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0, summary(report)
    per_tree = [len(sc.prototypes[i.prototype].lods) for i in sc.instances]
    try:
        g = clients.godot_import(files[".glb"])
        three = clients.three_load(files[".glb"])
    except clients.ClientMissing as e:
        pytest.skip(str(e))
    assert g["imported"], (g["reason"], g.get("log_tail"))
    assert not g["errors"], g["errors"]  # no "Skin bind ... no bone"
    assert len(g["skeletons"]) == sum(per_tree)
    bones = {s["path"]: s["bone_count"] for s in g["skeletons"]}
    assert len(g["mesh_instances"]) == sum(per_tree)
    for m in g["mesh_instances"]:
        assert m["skeleton_found"] and m["skin_binds"] == bones[m["path"].rsplit("/", 1)[0]]
    (anim,) = [a for p in g["animation_players"] for a in p["animations"]]
    assert anim["name"] == "wind_loop" and anim["loop"] and anim["tracks"] == anim["tracks_resolved"]
    assert anim["bones_moved"] > 0 and anim["loop_closes"]
    assert three["loaded"] and not three["warnings"], three.get("error") or three["warnings"]
    assert len(three["skeletons"]) == len(sc.instances)  # LOD0 of each (no MSFT_lod)
    (clip,) = three["animations"]
    assert clip["bones_moved"] > 0 and clip["loop_closes"]


def test_godot3_merges_same_seed_impostor_skins_unless_named_skins_are_off(tmp_path):
    """What the README tells Godot 3 users: a one-trunk species (joint `trunk_0`) and a
    several-trunk one (`trunk0_0`) from one seed have equal one-joint impostor skins under
    different joint names; Godot 3.2 merges them (it compares binds, not names) and one
    impostor's bind names a bone its skeleton lacks. With Use Named Skins off each skin binds
    its own skeleton's first bone: no error, every track resolved."""
    import clients

    data = no_camera(
        instances=[
            {"species": s, "position": [x, 0], "seed": 0}
            for s, x in ((POPLAR, 0), (str(SPECIES / "desert_bush.txt"), 8))
        ],
        scatter=[],
    )
    sc = build_scene(load_layout(write_layout(tmp_path, data)), workers=1, progress=False)
    path = tmp_path / "pair.glb"
    write_scene(sc, path)
    try:
        named = clients.godot_import(path)
        by_index = clients.godot_import(path, options={"skins/use_named_skins": False})
    except clients.ClientMissing as e:
        pytest.skip(str(e))
    assert named["imported"] and by_index["imported"]
    assert [e["message"] for e in named["errors"]] and all(
        "has no bone" in e["message"] for e in named["errors"]
    )
    assert not by_index["errors"], by_index["errors"]
    impostors = [m for m in by_index["mesh_instances"] if m["skin_binds"] == 1]
    assert len(impostors) == 2 and all(m["skeleton_found"] for m in impostors)
    (anim,) = [a for p in by_index["animation_players"] for a in p["animations"]]
    assert anim["tracks"] == anim["tracks_resolved"] and anim["loop_closes"]


def _geometry_bytes(path: Path) -> int:
    """The file's bytes less its embedded PNGs (stored alike by every --compress)."""
    gltf, _ = read_gltf(path)
    return path.stat().st_size - sum(
        gltf["bufferViews"][i["bufferView"]]["byteLength"] for i in gltf.get("images", [])
    )


def test_compressed_walk_forest_is_validator_clean_and_plays_in_three(walk, tmp_path):
    """`--compress quantize|meshopt` on the all-LOD forest: extensions required, validator
    clean, three.js (MeshoptDecoder for meshopt) loads every tree and plays the clip with every
    node within 1 mm × the largest instance scale of the float file's poses; geometry shrinks."""
    import clients
    from treegen_cli.exchange.validate import ValidatorUnavailable, summary, validate_gltf
    from treegen_cli.forest import gltf_options

    layout, sc, files = walk
    try:
        base = clients.three_load(files[".glb"], poses=4, timeout=300)
    except clients.ClientMissing as e:
        pytest.skip(str(e))
    bound = 1e-3 * max(i.scale for i in sc.instances)
    sizes = [_geometry_bytes(files[".glb"])]
    for c in ("quantize", "meshopt"):
        path = tmp_path / f"walk_{c}.glb"
        write_scene(sc, path, gltf_options(layout, c))
        gltf, _ = read_gltf(path)
        need = {"KHR_mesh_quantization", "KHR_texture_transform"} | (
            {"EXT_meshopt_compression"} if c == "meshopt" else set()
        )
        assert set(gltf["extensionsRequired"]) == need
        assert len(gltf["meshes"]) == sum(len(a.lods) for a in sc.prototypes)  # still shared
        try:
            report = validate_gltf(path)
        except ValidatorUnavailable as e:
            pytest.skip(str(e))
        assert report["issues"]["numErrors"] == 0 and report["issues"]["numWarnings"] == 0, summary(report)
        r = clients.three_load(path, poses=4, timeout=300)
        assert r["loaded"] and not r["warnings"], r.get("error") or r["warnings"]
        assert len(r["skeletons"]) == len(base["skeletons"]) == len(sc.instances)
        (clip,), (clip0,) = r["animations"], base["animations"]
        assert clip["tracks"] == clip0["tracks"] and clip["bones_moved"] > 0
        err = np.abs(np.asarray(clip["poses"]) - np.asarray(clip0["poses"])).max()
        assert err <= bound, (c, err)
        sizes.append(_geometry_bytes(path))
    assert sizes[0] > 1.4 * sizes[1] > 1.4 * 2 * sizes[2], sizes


def test_a_profile_budgets_every_prototype(tmp_path):
    """`defaults.profile` (and `--profile`, which wins) budgets the prototypes as `treegen
    make --profile` does: LOD0 within the row's triangles, the row's texture size; the
    layout keeps its joints and wind. `defaults.triangles` wins over the profile's; a bad
    profile names its JSON path and the allowed names, nothing written."""
    from treegen_cli.forest.options import make_options

    rush = str(SPECIES / "rush.txt")  # 68,339 triangles as the species is
    data = layout_dict(scatter=[], instances=[{"species": rush, "position": [0, 0], "seed": 1}])
    data["defaults"] = {**FAST, "profile": "mobile"}
    mobile = make_options(load_layout(write_layout(tmp_path, data)))
    assert mobile.budget.triangles == 20_000 and mobile.materials.texture_size == 256
    assert mobile.budget.ceiling  # a profile's budget brings heavier species down only
    assert mobile.rig.max_joints == FAST["max_joints"] and mobile.lod.distances == tuple(
        FAST["lod_distances"]
    )
    data["defaults"]["triangles"] = 9000
    typed = make_options(load_layout(write_layout(tmp_path, data))).budget
    assert typed.triangles == 9000 and not typed.ceiling  # a typed budget is a target
    data["defaults"].update(profile="web", triangles=None)  # --profile wins over the layout's
    del data["defaults"]["triangles"]
    write_layout(tmp_path, data)
    out = tmp_path / "f.glb"
    args = ["forest", str(tmp_path / "layout.json"), "-o", str(out), "--profile", "mobile", "--workers", "1"]
    from treegen_cli.progress import add_output_options

    add_output_options(cli)  # (main() adds -q/-v to every command)
    proc = CliRunner().invoke(cli, [*args, "-v"])
    assert proc.exit_code == 0, proc.output
    # -v: a line per prototype and the forest's stages (it printed nothing more than without)
    assert proc.output.count("  prototype rush seed 1: ") == 1, proc.output  # one (species, seed)
    assert "triangles per LOD, 12 joints" in proc.output and "  write " in proc.output, proc.output
    gltf, _ = read_gltf(out)
    lod0 = next(m for m in gltf["meshes"] if m["name"].endswith("_LOD0"))
    tris = sum(gltf["accessors"][p["indices"]]["count"] // 3 for p in lod0["primitives"])
    assert 18_000 <= tris <= 20_000  # the mobile row's 20,000, within the budget's 10 %
    data["defaults"]["profile"] = "phone"
    write_layout(tmp_path, data)
    import subprocess
    import sys

    main = "import sys; from treegen_cli.cli import main; main(sys.argv[1:])"
    bad = subprocess.run(
        [sys.executable, "-c", main, "forest", str(tmp_path / "layout.json"), "-o", str(tmp_path / "g.glb")],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1, bad.stderr
    assert 'defaults.profile: "phone"; expected one of mobile, web, desktop, hero' in bad.stderr
    assert not (tmp_path / "g.glb").exists()
    data["defaults"] = {**FAST, "triangles": 50}  # below the rush's minimum: named as set
    write_layout(tmp_path, data)
    low = subprocess.run(
        [
            sys.executable,
            "-c",
            main,
            "forest",
            str(tmp_path / "layout.json"),
            "-o",
            str(tmp_path / "g.glb"),
            "--workers",
            "1",
        ],
        capture_output=True,
        text=True,
    )
    assert low.returncode == 2 and "cannot come down to defaults.triangles 50" in low.stderr, low.stderr
    assert "--triangles" not in low.stderr and not (tmp_path / "g.glb").exists()


def test_forest_compress_refused_for_usd(tmp_path):
    import subprocess
    import sys

    layout = write_layout(tmp_path, no_camera(scatter=[]))
    out = tmp_path / "out"
    out.mkdir()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "treegen_cli",
            "forest",
            str(layout),
            "-o",
            str(out / "f.usdc"),
            "--compress",
            "meshopt",
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert "--compress meshopt is for .glb/.gltf only (USD has no such encoding" in proc.stderr
    assert not any(out.iterdir())


def test_camera_orders_the_walk_forest_nearest_first(scene, tmp_path):
    layout, baked = scene
    walk_sc = build_scene(layout, workers=1, progress=False)
    eff = [i.distance / i.scale for i in walk_sc.instances]
    assert eff == sorted(eff) and walk_sc.all_lods
    key = lambda i: (i.source, i.prototype, i.lod, i.variant)  # noqa: E731
    assert sorted(map(key, walk_sc.instances)) == sorted(map(key, baked.instances))


def test_200_trees_with_all_lods_cost_little_more_than_their_prototypes(tmp_path):
    """Issue 15: a 200-tree, 3-species forest with every LOD on every tree is no larger than
    1.2 × its prototypes' own files (what `treegen make` writes for each)."""
    from treegen_cli.exchange import export

    rush = str(SPECIES / "rush.txt")
    data = no_camera(
        instances=[],
        scatter=[
            {
                "species": [{"file": POPLAR}, {"file": PALM}, {"file": rush}],
                "rectangle": {"min": [-60, -60], "max": [60, 60]},
                "count": 200,
                "min_spacing": 4,
                "seed": 7,
                "variants": 1,
            }
        ],
    )
    sc = build_scene(load_layout(write_layout(tmp_path, data)), workers=1, progress=False)
    assert len(sc.instances) == 200 and len(sc.prototypes) == 3
    assert all(len(a.lods) == 3 + 1 for a in sc.prototypes)  # + the impostor
    forest = sum(p.stat().st_size for p in write_scene(sc, tmp_path / "f.glb"))
    own = sum(
        p.stat().st_size for k, a in enumerate(sc.prototypes) for p in export(a, tmp_path / f"p{k}.glb")
    )
    assert forest <= 1.2 * own, (forest, own)


# ----------------------------------------------------------------------------- preview of a layout

ROW = [-12, 0, 12]  # three poplars in a row, across the camera's view


def row_layout(**over) -> dict:
    return layout_dict(
        camera={"position": [0, -45, 5], "target": [0, 0, 8], "fov_deg": 60, "width_px": 1280},
        instances=[{"species": POPLAR, "position": [x, 0], "seed": 1} for x in ROW],
        scatter=[],
        **over,
    )


@pytest.fixture(scope="module")
def row_view(tmp_path_factory):
    """The row layout's preview, drawn in this process: (image, camera, summary)."""
    from treegen_cli.preview import PreviewOptions, render_still
    from treegen_cli.preview_forest import forest_view

    path = write_layout(tmp_path_factory.mktemp("row"), row_layout())
    options = PreviewOptions(width=240, height=135, sun_azimuth=-90.0, sun_elevation=85.0)
    scene, camera, summary = forest_view(path, options.azimuth, options.elevation, 240 / 135, workers=1)
    return render_still(scene, options, camera=camera), camera, summary


def _columns(camera, width: int, height: int, points_z_up) -> np.ndarray:
    """Pixel columns of world points (Z up) seen by the preview camera."""
    from treegen_cli.axes import Z_UP_TO_Y_UP

    p = np.asarray(points_z_up, float) @ Z_UP_TO_Y_UP.T
    clip = np.c_[p, np.ones(len(p))] @ camera.view_proj(width / height).T
    return (clip[:, 0] / clip[:, 3] * 0.5 + 0.5) * width


def _layout_columns(layout_camera: dict, width: int, points) -> np.ndarray:
    """Pixel columns of points (Z up) on a `width`-pixel image from the layout's own pinhole
    camera: `fov_deg` spans the image's width (independent of the preview's Camera)."""
    eye, target = np.array(layout_camera["position"], float), np.array(layout_camera["target"], float)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    rel = np.asarray(points, float) - eye
    tangent = (rel @ right) / (rel @ forward)
    return width / 2 * (1 + tangent / np.tan(np.radians(layout_camera["fov_deg"]) / 2))


def test_layout_preview_draws_each_tree_where_the_layout_puts_it(row_view):
    """`treegen preview LAYOUT.json`: from the layout's camera, each poplar shows as tree
    pixels (not sky) in the column its position projects to, with sky between them; all
    three at the LOD the camera needs (25-60 m: LOD1)."""
    img, camera, summary = row_view
    assert summary == {
        "trees": 3,
        "prototypes": 1,
        "trees_per_lod": [0, 3, 0, 0],
        "camera": "layout",
    }  # 45 m: LOD1
    h, w = img.shape[:2]
    rgb = img.astype(float)
    sky = (rgb[..., 2] > rgb[..., 1] + 8) & (rgb[..., 2] > rgb[..., 0] + 8)
    band = slice(int(0.15 * h), int(0.45 * h))  # rows of the crowns, above the horizon
    cam = row_layout()["camera"]
    trees = _layout_columns(cam, w, [[x, 0, 10] for x in ROW])
    gaps = _layout_columns(cam, w, [[x, 0, 10] for x in (-6, 6)])
    assert np.allclose(trees, _columns(camera, w, h, [[x, 0, 10] for x in ROW]), atol=0.5)
    for c in trees:
        assert not sky[band, int(c) - 2 : int(c) + 3].all(axis=0).any(), c  # a tree in every column
    for c in gaps:
        assert sky[band, int(c)].mean() > 0.5, c  # sky between them


def test_layout_preview_shades_each_tree_by_its_own_crown(row_view):
    """Each tree's sky light is dimmed inside its own crown (Part.crown), as a single tree's
    preview does: the middle poplar is as bright as its neighbours under a sun from overhead.
    With one crown around the whole row it came out darker (it sat in that crown's core)."""
    img, camera, _summary = row_view
    h, w = img.shape[:2]
    rgb = img.astype(float)
    lum = rgb @ [0.2126, 0.7152, 0.0722]
    sky = (rgb[..., 2] > rgb[..., 1] + 8) & (rgb[..., 2] > rgb[..., 0] + 8)
    band = slice(int(0.15 * h), int(0.45 * h))
    means = []
    for c in _columns(camera, w, h, [[x, 0, 10] for x in ROW]):
        cols = slice(int(c) - 6, int(c) + 7)
        tree = ~sky[band, cols]
        means.append(lum[band, cols][tree].mean())
    left, middle, right = means
    assert abs(middle / ((left + right) / 2) - 1) < 0.04, means  # one crown: 9 % darker


def test_layout_preview_without_a_camera_frames_every_tree(tmp_path, monkeypatch):
    """With no camera, the preview frames every tree's box from --azimuth/--elevation and
    picks each tree's LOD by its distance to that camera, as the layout's camera would."""
    from treegen_cli.preview_forest import bearing, forest_view

    data = no_camera(instances=[{"species": POPLAR, "position": [x, 0], "seed": 1} for x in ROW], scatter=[])
    scene, camera, summary = forest_view(write_layout(tmp_path, data), -90.0, 20.0, 16 / 9, workers=1)
    assert summary["camera"] == "framed" and summary["trees"] == 3
    cols = _columns(camera, 160, 90, [[x, 0, z] for x in (-14, 14) for z in (0, 20)])
    assert (cols > 0).all() and (cols < 160).all(), cols
    assert sorted({round(float(p.crown[0][0])) for p in scene.parts}) == ROW  # a crown each tree
    assert bearing(camera) == pytest.approx(-90.0)  # the default sun stands as for one tree
    from treegen_cli import preview_forest

    monkeypatch.setattr(preview_forest, "MAX_TRIANGLES", 1000)  # too many: refused, by name
    with pytest.raises(
        TreegenError, match=r"layout.json: the trees this camera sees come to [\d,]+ triangles"
    ):
        forest_view(write_layout(tmp_path, data), -90.0, 20.0, 16 / 9, workers=1)


def test_layout_preview_cli_writes_a_png_and_refuses_tree_only_flags(tmp_path):
    import subprocess
    import sys

    path = write_layout(tmp_path, row_layout())
    out = tmp_path / "row.png"
    run = [sys.executable, "-m", "treegen_cli", "preview", str(path)]
    proc = subprocess.run([*run, "-o", str(out), "--size", "96x54", "--json"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    summary = json.loads(proc.stdout)
    assert summary["trees"] == 3 and summary["image"] == str(out) and out.stat().st_size > 0
    for flag in (["--animate", str(tmp_path / "a.gif")], ["--lod", "2"]):
        bad = subprocess.run([*run, "-o", str(tmp_path / "x.png"), *flag], capture_output=True, text=True)
        assert bad.returncode == 2 and f"{flag[0]}: not for a forest layout" in bad.stderr, bad.stderr
        assert "Traceback" not in bad.stderr and not (tmp_path / "x.png").exists()
    # the row layout has a camera: --azimuth/--elevation, which frame a camera-less layout,
    # are refused by name instead of silently ignored (given at their defaults too)
    bad = subprocess.run(
        [*run, "-o", str(tmp_path / "x.png"), "--azimuth", "-90", "--elevation", "30"],
        capture_output=True,
        text=True,
    )
    assert bad.returncode == 2 and "--azimuth and --elevation frame a layout without a camera" in bad.stderr
    assert "Traceback" not in bad.stderr and not (tmp_path / "x.png").exists()


def test_layout_impostor_distance_places_every_prototypes_impostor(tmp_path):
    """defaults.impostor_distance sets each prototype's impostor switch in metres, as `make
    --impostor-distance` does; nearer than a prototype's last LOD it is refused by its key."""
    one = [{"species": POPLAR, "position": [0, 0], "seed": 1}]
    far = {**FAST, "impostor_distance": 150}
    sc = build_scene(
        load_layout(write_layout(tmp_path, layout_dict(instances=one, scatter=[], defaults=far))),
        workers=1,
        progress=False,
    )
    assert [lod.distance for lod in sc.prototypes[0].lods] == [0, 25, 60, 150]
    near = {**FAST, "impostor_distance": 40}
    layout = load_layout(
        write_layout(tmp_path, layout_dict(instances=one, scatter=[], defaults=near), "near.json")
    )
    with pytest.raises(
        TreegenError,
        match=r"^\S*near\.json: defaults\.impostor_distance 40: the impostor comes after the last LOD, "
        r"used from 60 m.* \(on \S*poplar\S*\)$",
    ):  # the layout's file and key, the tree it failed on (it was the species file's name)
        build_scene(layout, workers=1, progress=False)


def test_a_layout_saved_with_a_byte_order_mark_reads_as_without(tmp_path):
    """Some Windows editors save UTF-8 with a byte-order mark; json refused it ("Unexpected
    UTF-8 BOM"). Layouts and catalogues (one reader) skip it."""
    plain = write_layout(tmp_path, layout_dict(), "plain.json")
    marked = tmp_path / "marked.json"
    marked.write_bytes(b"\xef\xbb\xbf" + plain.read_bytes())
    assert load_layout(marked).placements == load_layout(plain).placements


def test_a_species_refused_while_building_is_named_by_layout_and_json_path(tmp_path):
    """A species file's own error found only when its prototype is built (an implausible
    Scale, a budget it cannot come down to) names the layout and the JSON path that names the
    file, not the species file alone."""
    import subprocess
    import sys

    big = tmp_path / "bigpalm.txt"
    big.write_text((SPECIES / "palm.txt").read_text().replace("\nScale          12.0", "\nScale 900"))
    layout = write_layout(tmp_path, {"instances": [{"species": "bigpalm.txt", "position": [0, 0]}]})
    out = tmp_path / "f.glb"
    main = "import sys; from treegen_cli.cli import main; main(sys.argv[1:])"
    proc = subprocess.run(
        [sys.executable, "-c", main, "forest", str(layout), "-o", str(out)], capture_output=True, text=True
    )
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, proc.stderr
    assert proc.stderr.startswith(f"treegen: error: {layout}: instances[0].species: {big}:"), proc.stderr
    assert "Scale = 900" in proc.stderr and not out.exists()
    # a file whose name starts with another's is not mistaken for it (a.txt, a.txt2)
    (tmp_path / "a.txt").write_text((SPECIES / "palm.txt").read_text())
    (tmp_path / "a.txt2").write_text(big.read_text())
    two = [{"species": "a.txt", "position": [0, 0]}, {"species": "a.txt2", "position": [9, 0]}]
    layout = write_layout(tmp_path, {"instances": two})
    proc = subprocess.run(
        [sys.executable, "-c", main, "forest", str(layout), "-o", str(out)], capture_output=True, text=True
    )
    assert f"{layout}: instances[1].species: {tmp_path / 'a.txt2'}:" in proc.stderr, proc.stderr


def test_forest_workers_die_of_sigterm_not_of_the_clis_handler():
    """The CLI raises errors.Terminated on SIGTERM; forked forest workers inherit that handler
    and, terminated by their parent, printed a traceback or ran their next task. Their
    initializer restores the default."""
    import subprocess
    import sys

    code = (
        "import signal; from treegen_cli.errors import raise_terminated; "
        "signal.signal(signal.SIGTERM, raise_terminated); "
        "from treegen_cli.executor import _worker_start; _worker_start(); "
        "print(signal.getsignal(signal.SIGTERM) is signal.SIG_DFL, signal.getsignal(signal.SIGINT) is signal.SIG_IGN)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "True"], out
