"""Real clients nobody on the project wrote (tests/clients.py): every bundled species' default
GLB (and two species' `--lod-files` parts) through Godot 3.2's editor import, three.js and
Babylon.js.

What a user sees after import is asserted: the import finishes, one skeleton per LOD in the
file within the joint budget, leaves and bark with normals, UVs in range, the wind clip named
so Godot loops it and moving bones, no importer errors. A client that is not installed skips
its tests with the install command (CI installs all three: `make install`).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import pytest

import clients
from conftest import SPECIES, run_treegen, species_path

MAX_BONES = 256
UV_LIMIT = 64.0  # engines store UVs as half floats


# species whose `--lod-files` parts are imported too: every default file already carries all
# five LODs through each importer, and the parts' writer path does not depend on the species
# (an import of every species' parts doubled the suite's Godot time)
PARTS = ["quaking_aspen", "balsam_fir"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """{species: (default GLB, [LOD parts] for PARTS, else [])}, made two processes at a time."""
    out = tmp_path_factory.mktemp("clients")

    def make(name):
        one, parts = out / f"{name}.glb", out / "parts" / f"{name}.glb"
        parts.parent.mkdir(exist_ok=True)
        for args in ([one], [parts, "--lod-files"])[: 2 if name in PARTS else 1]:
            proc = run_treegen("make", species_path(name), "-o", *args, "-q")
            assert proc.returncode == 0, proc.stderr
        return name, (one, sorted(parts.parent.glob(f"{name}_LOD*.glb")))

    with ThreadPoolExecutor(2) as pool:
        return dict(pool.map(make, SPECIES))


def _call(fn, *args, **kw):
    try:
        return fn(*args, **kw)
    except clients.ClientMissing as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="module")
def godot(files):
    every = [p for one, parts in files.values() for p in [one, *parts]]
    return _call(clients.godot_import_many, every, timeout=900)


def _godot_checks(r, n_lods, sways=True, impostor=1):
    """`n_lods` skeletons and clips, of which `impostor` (0 or 1) are the impostor's cards."""
    assert r["imported"], (r["reason"], r.get("log_tail"))
    assert not r["errors"], r["errors"]
    skeletons = r["skeletons"]
    assert len(skeletons) == n_lods, [s["path"] for s in skeletons]
    assert all(0 < s["bone_count"] <= MAX_BONES for s in skeletons)
    surfaces = [s for m in r["mesh_instances"] for s in m["surfaces"]]
    bark = [s for s in surfaces if s["material"]["name"] == "bark"]
    assert len(bark) == n_lods - impostor  # (+ leaves, where the species has any)
    cards = [s for s in surfaces if s["material"]["name"] == "impostor"]
    assert len(cards) == impostor
    for s in cards:  # cut-out cards on atlas cells, one face each way
        assert all(0 <= v <= 1 for v in s["uv_min"] + s["uv_max"])
        m = s["material"]
        assert m["albedo_texture"] and m["alpha_scissor"] and 0 < m["alpha_scissor_threshold"] < 1, m
    for s in surfaces:
        assert s["has_normal"] and s["zero_normals"] == 0
        assert all(abs(v) <= UV_LIMIT for v in s["uv_min"] + s["uv_max"]), s
    leaves = [s for s in surfaces if s["material"]["name"] == "leaf"]
    for s in leaves:  # cut-out leaf texture, UVs inside the atlas
        assert all(0 <= v <= 1 for v in s["uv_min"] + s["uv_max"])
        m = s["material"]
        assert m["albedo_texture"] and m["alpha_scissor"] and 0 < m["alpha_scissor_threshold"] < 1, m
        assert m["cull_mode"] == "disabled"
    for s in bark:
        assert s["material"]["albedo_texture"] and s["material"]["normal_texture"], s["material"]
    anims = [a for p in r["animation_players"] for a in p["animations"]]
    assert len(anims) == n_lods
    for a in anims:
        assert a["name"].endswith("_loop") and a["loop"], a["name"]
        assert a["loop_closes"] and a["tracks"] == a["tracks_resolved"]
    # the full-detail clip sways; a far LOD may keep no motion where none would show on screen
    assert not sways or next(a for a in anims if a["name"] == "wind_loop")["bones_moved"] > 0


@pytest.mark.parametrize("species", SPECIES)
def test_godot_imports_the_default_file(godot, files, species):
    _godot_checks(godot[str(files[species][0])], 5)  # 4 LODs + the impostor


@pytest.mark.parametrize("species", PARTS)
def test_godot_imports_each_lod_file(godot, files, species):
    parts = files[species][1]
    assert [p.stem for p in parts] == [f"{species}_LOD{k}" for k in range(5)]
    for k, p in enumerate(parts):
        _godot_checks(godot[str(p)], 1, sways=k == 0, impostor=int(k == 4))


def _web_checks(r, n_skinned_lods=1, far: bool | None = False, loop_tol=None):
    """`far`: the impostor's file, whose one joint's sway is decimated for ~300 m (a handful of
    keys, ~1 px of motion): it moves, but may be still at the client's sample time. `loop_tol`:
    int16 keys (compressed files), unit quaternions to ~1e-5, which three.js renormalizes on
    some paths only."""
    assert r["loaded"], r.get("error")
    assert not [w for w in r["warnings"] if "ormals" in w or "No target node" in w], r["warnings"]
    assert r["skeletons"] and all(0 < s["bones"] <= MAX_BONES for s in r["skeletons"])
    meshes = [m for m in r["meshes"] if m.get("skinned", True)]
    assert meshes and all(m["has_normal"] for m in meshes)
    for m in r["materials"]:
        assert m["base_color_texture"], m
        if m["name"] == "leaf":  # alpha-tested cut-out, both faces drawn
            if "alpha_test" in m:  # three.js
                assert m["alpha_test"] > 0 and m["double_sided"], m
            else:  # Babylon: ALPHATEST mode
                assert m["transparency_mode"] == 1 and not m["back_face_culling"], m
        if m["name"] == "bark":
            assert m["normal_texture"], m
        if m["name"] == "impostor":  # cut-out cards, single-sided twins
            if "alpha_test" in m:
                assert m["alpha_test"] > 0 and not m["double_sided"], m
            else:
                assert m["transparency_mode"] == 1 and m["back_face_culling"], m
    anims = {a["name"]: a for a in r["animations"]}
    wind = anims["wind_loop"]
    if far is not None:  # None: a lower LOD of a short clip, which may hold its end keys only
        assert wind["max_local_change"] > 0 if far else wind["bones_moved"] > 0
    if loop_tol is None:
        assert wind["loop_closes"]
    else:
        assert wind["loop_max_diff"] <= loop_tol


@pytest.fixture(scope="module")
def web(files):
    every = [one for one, _ in files.values()] + files["quaking_aspen"][1]

    def load(p):
        return str(p), (_call(clients.three_load, p), _call(clients.babylon_load, p))

    with ThreadPoolExecutor(2) as pool:
        return dict(pool.map(load, every))


@pytest.mark.parametrize("species", SPECIES)
def test_three_and_babylon_load_and_play(web, files, species):
    three, babylon = web[str(files[species][0])]
    _web_checks(three)
    _web_checks(babylon)
    # Babylon reads MSFT_lod as progressive loading, not distance switching: every level
    # loads, coarsest first (its event 0 is the impostor, 4 is LOD0), and each finer one
    # replaces the one before, so once loading completes LOD0 alone is left (the README
    # says so); three.js reads LOD0 only
    assert babylon["msft_lod_levels_loaded"] == [0, 1, 2, 3, 4]
    assert {m["name"].split("_primitive")[0] for m in babylon["meshes"]} == {f"{species}_LOD0"}
    assert [s["name"] for s in babylon["skeletons"] if s["meshes"]] == [f"{species}_LOD0_skin"]


def test_lod_files_load_in_three_and_babylon(web, files):
    for k, p in enumerate(files["quaking_aspen"][1]):
        three, babylon = web[str(p)]
        # LOD0 sways; LOD1-3 (57-287 m) and the impostor (430 m) of this short clip may keep
        # only their end keys (the impostor's sway: test_impostor)
        far = False if k == 0 else None
        _web_checks(three, far=far)
        _web_checks(babylon, far=far)
        assert len(three["skeletons"]) == 1 and len(three["animations"]) == 1


# ---- --compress quantize / meshopt (two species: the suite's time matters) ----

COMPRESSED = ["quaking_aspen", "palm"]
SHORT = ["--duration", "2", "--fps", "10"]


@pytest.fixture(scope="module")
def compressed(tmp_path_factory):
    """{(species, compress): path}, plus ("quaking_aspen", "meshopt-parts"): its LOD files."""
    out = tmp_path_factory.mktemp("compressed")

    def make(key):
        name, compress = key
        p = out / f"{name}_{compress}.glb"
        proc = run_treegen("make", species_path(name), "-o", p, "--compress", compress, *SHORT, "-q")
        assert proc.returncode == 0, proc.stderr
        return key, [p]

    keys = [(n, c) for n in COMPRESSED for c in ("quantize", "meshopt")]
    with ThreadPoolExecutor(2) as pool:
        made = dict(pool.map(make, keys))
    parts = out / "parts" / "quaking_aspen.glb"
    parts.parent.mkdir()
    proc = run_treegen(
        "make",
        species_path("quaking_aspen"),
        "-o",
        parts,
        "--lod-files",
        "--compress",
        "meshopt",
        *SHORT,
        "-q",
    )
    assert proc.returncode == 0, proc.stderr
    made["quaking_aspen", "meshopt-parts"] = sorted(parts.parent.glob("quaking_aspen_LOD*.glb"))
    return made


@pytest.fixture(scope="module")
def compressed_web(compressed):
    every = [p for paths in compressed.values() for p in paths]

    def load(p):
        return str(p), (_call(clients.three_load, p), _call(clients.babylon_load, p))

    with ThreadPoolExecutor(2) as pool:
        return dict(pool.map(load, every))


@pytest.mark.parametrize("species", COMPRESSED)
@pytest.mark.parametrize("compress", ["quantize", "meshopt"])
def test_compressed_files_load_and_play(compressed, compressed_web, species, compress):
    """three.js (GLTFLoader + MeshoptDecoder) and Babylon.js (NullEngine, meshoptimizer's
    decoder) load, skin and play the file; the Khronos validator reports no error."""
    from treegen_cli.exchange.validate import summary, validate_gltf

    path = compressed[species, compress][0]
    three, babylon = compressed_web[str(path)]
    _web_checks(three, loop_tol=1e-3)
    _web_checks(babylon, loop_tol=1e-3)
    assert "KHR_mesh_quantization" in three["extensions_required"]
    assert ("EXT_meshopt_compression" in three["extensions_required"]) == (compress == "meshopt")
    assert babylon["msft_lod_levels_loaded"] == [0, 1, 2, 3, 4]  # 4 LODs + the impostor
    assert all(m["vertices"] > 0 for m in three["meshes"] + babylon["meshes"])
    report = validate_gltf(path)
    assert report["issues"]["numErrors"] == 0, summary(report)


def test_compressed_lod_files_load_and_play(compressed, compressed_web):
    parts = compressed["quaking_aspen", "meshopt-parts"]
    assert [p.stem for p in parts] == [f"quaking_aspen_LOD{k}" for k in range(5)]
    for p in parts:
        three, babylon = compressed_web[str(p)]
        assert three["loaded"] and babylon["loaded"], (three.get("error"), babylon.get("error"))
        assert "EXT_meshopt_compression" in three["extensions_required"]
        assert len(three["skeletons"]) == 1 and len(three["animations"]) == 1
    _web_checks(compressed_web[str(parts[0])][0], loop_tol=1e-3)
    _web_checks(compressed_web[str(parts[0])][1], loop_tol=1e-3)


def test_godot_imports_a_gltf_with_its_png_files(tmp_path):
    """A .gltf names its textures as PNG files beside it (and its .bin): Godot's import of the
    folder finds them, every check the GLB passes included. Godot 3.2 does not decode URIs:
    a name's parentheses stay as they are in them (r%281%29.bin was not found); a name with a
    space fails there as any spec-correct .gltf's would (README)."""
    path = tmp_path / "rush(1).gltf"
    proc = run_treegen("make", species_path("rush"), "-o", path, "-q")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in tmp_path.glob("*.png")) and not list(tmp_path.glob("*.glb"))
    _godot_checks(_call(clients.godot_import, path), 5)
