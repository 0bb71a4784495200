"""Triangle budgets (`--triangles`, budget.py), the `--joints` alias and `--profile` presets
(profiles.py): counts are those of real built meshes, refusals one line with exit code 2."""

from __future__ import annotations

import json
from dataclasses import replace
from functools import lru_cache

import pytest

from conftest import PAPER_SPECIES, ROOT, SPECIES, grown, run_treegen, species_path

BUDGET = 20_000


@lru_cache(maxsize=None)
def budget_build(name: str, triangles: int):
    """LOD0 of the species built through the real pipeline with a triangle budget (no wind,
    no LODs, colour materials: only the mesh is measured); a TreegenError is returned."""
    from treegen_cli.budget import BudgetOptions
    from treegen_cli.errors import TreegenError
    from treegen_cli.materials import MaterialOptions
    from treegen_cli.params import load_params
    from treegen_cli.pipeline import MakeOptions, build_asset

    options = MakeOptions(
        wind=None,
        lod=None,
        materials=MaterialOptions(textures=False),
        budget=BudgetOptions(triangles=triangles),
    )
    try:
        asset, tree = build_asset(load_params(species_path(name)), 0, options)
    except TreegenError as e:
        return e
    return sum(len(p.indices) // 3 for p in asset.lods[0].primitives), tree


@pytest.mark.parametrize("name", ["quaking_aspen", "palm", "rush", "fine_trunk"])
def test_triangle_estimate_is_the_mesh(name):
    """limits.estimate_triangles, the budget's size model, counts what build_mesh emits (and
    estimate_vertices its vertices): fine_trunk, the aspen's trunk in 50 segments, puts flare
    rings on node rings, which the mesh merges (info said 87,240 where make built 87,160)."""
    from treegen_cli.generate import generate
    from treegen_cli.limits import estimate_triangles, estimate_vertices
    from treegen_cli.mesh import MESH_DEFAULTS, build_mesh
    from treegen_cli.params import load_params
    from treegen_cli.rig import build_rig

    if name == "fine_trunk":
        p = load_params(species_path("quaking_aspen"))
        level0 = replace(p.level[0], curve_res=50, curve=3600.0)
        tree = generate(replace(p, level=(level0, *p.level[1:])), 0)
    else:
        tree = grown(name)
    rig = build_rig(tree)
    for mesh in (
        MESH_DEFAULTS,
        replace(MESH_DEFAULTS, sides=(5, 3), rings_per_segment=(1,)),
        replace(MESH_DEFAULTS, leaf_geometry="shape"),
    ):
        prims = build_mesh(tree, rig, mesh)
        built = [len(p.indices) // 3 for p in prims]
        bark, leaves = estimate_triangles(tree, mesh)
        assert built == ([bark, leaves] if leaves else [bark])
        bark_v, leaf_v = estimate_vertices(tree, mesh)
        assert [len(p.positions) for p in prims] == ([bark_v, leaf_v] if leaf_v else [bark_v])


@pytest.mark.parametrize("name", SPECIES)
def test_every_species_meets_the_budget_or_names_its_minimum(name):
    from treegen_cli.budget import BudgetOptions, plan_budget
    from treegen_cli.errors import TreegenError
    from treegen_cli.mesh import MESH_DEFAULTS
    from treegen_cli.params import load_params

    result = budget_build(name, BUDGET)
    if isinstance(result, TreegenError):
        assert "--triangles 20,000" in str(result)
        minimum = int(str(result).rsplit("use --triangles ", 1)[1].split()[0])
        assert minimum > BUDGET
        return
    triangles, tree = result
    assert 0.9 * BUDGET <= triangles <= BUDGET, (name, triangles)
    # the plan's count is the built count, so the estimate can be trusted before building
    plan = plan_budget(load_params(species_path(name)), 0, MESH_DEFAULTS, BudgetOptions(triangles=BUDGET))
    assert plan.triangles == triangles
    assert tree.params == plan.params


@pytest.mark.parametrize("triangles", [1500, 3000])
def test_a_tree_whose_leaves_round_away_still_counts_them(triangles):
    """pair_small has so few leaves that at the lowest LeafQuality factor none is grown: the
    plan counts them at factor 1 instead of taking the tree for leafless, so the build (which
    grows them) stays within [0.9 N, N] (it built 1,506 for --triangles 1500) and the plan's
    count is the built count."""
    from treegen_cli.budget import BudgetOptions, plan_budget
    from treegen_cli.materials import MaterialOptions
    from treegen_cli.mesh import MESH_DEFAULTS
    from treegen_cli.params import load_params
    from treegen_cli.pipeline import MakeOptions, build_asset

    params = load_params(ROOT / "tests" / "fixtures" / "pair_small.txt")
    budget = BudgetOptions(triangles=triangles)
    options = MakeOptions(wind=None, lod=None, materials=MaterialOptions(textures=False), budget=budget)
    asset, tree = build_asset(params, 2, options)
    built = sum(len(p.indices) // 3 for p in asset.lods[0].primitives)
    assert tree.n_leaves > 0 and 0.9 * triangles <= built <= triangles, built
    assert plan_budget(params, 2, MESH_DEFAULTS, budget).triangles == built


def test_budget_keeps_leaf_area_and_refines_small_trees():
    """Coarsening keeps the species' leaf area (fewer, larger leaves); a tree under its budget
    gets more, smaller leaves instead of staying short of it."""
    full = float(grown("weeping_willow").leaf_area.sum())
    triangles, tree = budget_build("weeping_willow", BUDGET)
    assert tree.n_leaves < grown("weeping_willow").n_leaves / 20
    assert float(tree.leaf_area.sum()) == pytest.approx(full, rel=0.02)
    n, palm = budget_build("fan_palm", BUDGET)  # 8,360 triangles as the species is
    assert palm.n_leaves > grown("fan_palm").n_leaves
    assert float(palm.leaf_area.sum()) == pytest.approx(float(grown("fan_palm").leaf_area.sum()), rel=0.02)


def test_budget_keeps_the_willows_whips_and_each_species_leaves():
    """At 20,000 triangles the weeping willow keeps its hanging whips (a third stem level,
    coarser curves) rather than two levels dropped, which left an upright bush; and no species'
    budget gives its leaves less than half their share of the species' own triangles (the
    bark/leaf split is held both ways: a 4-level sassafras with 624 leaves is not a choice)."""
    from treegen_cli.budget import BudgetOptions, plan_budget
    from treegen_cli.mesh import MESH_DEFAULTS
    from treegen_cli.params import load_params

    _, willow = budget_build("weeping_willow", BUDGET)
    assert int(willow.stem_level.max()) == 2  # levels 0-2: trunk, limbs, whips
    for name in ("weeping_willow", "sassafras", "ca_black_oak", "quaking_aspen"):
        plan = plan_budget(load_params(species_path(name)), 0, MESH_DEFAULTS, BudgetOptions(triangles=BUDGET))
        full = grown(name)
        own = full.n_leaves * 2 / (full.n_leaves * 2 + _bark(name))  # cards: 2 triangles
        assert plan.leaves / plan.triangles >= 0.5 * own, (name, plan.describe())


def _bark(name: str) -> int:
    from treegen_cli.limits import estimate_triangles
    from treegen_cli.mesh import MESH_DEFAULTS

    return estimate_triangles(grown(name), MESH_DEFAULTS)[0]


def test_refusal_names_the_minimum_and_the_minimum_builds(tmp_path):
    out = tmp_path / "a.glb"
    r = run_treegen("make", species_path("quaking_aspen"), "-o", out, "--triangles", "300")
    assert r.returncode == 2 and not out.exists()
    line = r.stderr.strip()
    assert "\n" not in line and "--triangles 300" in line and "quaking_aspen" in line
    minimum = int(line.rsplit("use --triangles ", 1)[1].split()[0])
    assert 300 < minimum < 5_000
    triangles, _ = budget_build("quaking_aspen", minimum)
    assert 0.9 * minimum <= triangles <= minimum
    # `info --triangles` prints the same plan (and the same refusal) without building
    info = run_treegen("info", species_path("quaking_aspen"), "--triangles", minimum, "--json")
    assert json.loads(info.stdout)["triangles"]["budget"]["triangles"] == triangles
    r = run_treegen("info", species_path("quaking_aspen"), "--triangles", "300")
    assert r.returncode == 2 and r.stderr.strip() == line


def test_info_says_its_rows_are_the_tree_as_grown_when_a_budget_regrows_it():
    """`info --profile mobile` reported the tupelo's 10,411 stems and 241,942 triangles, the
    tree as grown, where `make` builds 18,996 triangles (the budget line said so, the rows
    did not): its title says the rows are as grown, and only when a budget regrows the tree
    (a species under a profile's ceiling is built as it is)."""
    runs = [("black_tupelo", "--profile", "mobile"), ("black_tupelo",), ("fan_palm", "--profile", "mobile")]
    titles = [run_treegen("info", species_path(name), *args).stdout.splitlines()[0] for name, *args in runs]
    grown = [t.endswith("as grown: `make` builds the budget's tree, below)") for t in titles]
    assert grown == [True, False, False], titles


def _make_json(*args) -> dict:
    r = run_treegen("make", *args, "--json", "-q")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


@pytest.mark.parametrize("name", PAPER_SPECIES)
def test_mobile_profile_on_the_paper_species(tmp_path, name):
    from treegen_cli import api
    from treegen_cli.profiles import PROFILES

    s = api.make(species_path(name), tmp_path / "t.glb", profile="mobile")
    mobile = PROFILES["mobile"]
    assert 18_000 <= s["triangles"] <= 20_000 and s["joints"] <= 64  # all far larger as is
    screen = [float(x) for x in str(mobile["lod_screen"]).split(",")]
    assert len(s["lods"]) == len(screen) + 2  # LOD0, one per switch, the impostor
    assert s["lods"][-1]["triangles"] == 8  # the impostor's crossed cards
    distances = [r["distance_m"] for r in s["lods"]]
    assert distances[0] == 0.0 and distances == sorted(distances)
    assert s["keys"] == mobile["duration"] * mobile["fps"] + 1
    tris = [r["triangles"] for r in s["lods"]]
    assert tris == sorted(tris, reverse=True), tris  # LODs never add triangles
    assert all(r["joints"] <= 64 for r in s["lods"])


def test_a_profiles_budget_never_makes_a_species_heavier(tmp_path):
    """A profile's triangles are a ceiling: the fan palm (8,360 as it is) and shave grass
    (13,520) stay as their files say under mobile's 20,000, where a typed --triangles 20000
    is a target and grows them into [18,000, 20,000]; make, info and a catalogue agree."""
    from treegen_cli import api
    from treegen_cli.batch import parse_catalogue
    from treegen_cli.limits import estimate_triangles
    from treegen_cli.mesh import MESH_DEFAULTS

    for name in ("fan_palm", "shave_grass"):
        own = sum(estimate_triangles(grown(name), MESH_DEFAULTS))
        assert own < 20_000
        s = api.make(species_path(name), tmp_path / f"{name}.glb", profile="mobile", no_wind=True)
        assert s["lods"][0]["triangles"] == own, (name, s["lods"][0])
        budget = api.info(species_path(name), profile="mobile")["triangles"]["budget"]
        assert budget["as_is"] and budget["triangles"] == own and budget["minimum"] is None
    typed = api.make(species_path("fan_palm"), tmp_path / "t.glb", profile="mobile", triangles=20_000)
    assert 18_000 <= typed["lods"][0]["triangles"] <= 20_000
    assert not api.info(species_path("fan_palm"), triangles=20_000)["triangles"]["budget"]["as_is"]
    data = {"defaults": {"profile": "mobile"}, "entries": [{"species": str(species_path("fan_palm"))}]}
    (r,) = parse_catalogue(data, tmp_path / "c.json").resolved.values()
    assert r.options.budget.ceiling and r.options.budget.triangles == 20_000


def test_a_budget_the_bark_nearly_fills_keeps_leaves_in_what_is_left():
    """Arbaro's wheat at the mobile profile's 20,000: its 49 stalks' bark takes 19,404 at the
    coarsest; the plan aimed the leaves at the window's middle (19,000), below the bark, and
    kept 7 grains grown 16× (green discs around the plant). The leaves take most of the room
    left below the budget instead: LeafQuality about ×1/8, hundreds of grains, still under
    20,000; and a larger budget never keeps fewer leaves (20,430 kept 7 where 20,420 kept 486)."""
    from treegen_cli.budget import BudgetOptions, plan_budget
    from treegen_cli.mesh import MESH_DEFAULTS
    from treegen_cli.params import load_params

    params = load_params(ROOT / "tests" / "fixtures" / "arbaro" / "wheat.xml")
    plan = plan_budget(params, 0, MESH_DEFAULTS, BudgetOptions(triangles=20_000, ceiling=True))
    assert plan.bark > 19_000 and plan.triangles <= 20_000
    assert plan.leaf_factor >= 0.1 and plan.leaves >= 400, plan.describe()
    leaves = [
        plan_budget(params, 0, MESH_DEFAULTS, BudgetOptions(triangles=t)).leaves for t in (20_420, 20_430)
    ]
    assert plan.leaves < leaves[0] <= leaves[1], leaves


def test_a_budget_probes_past_a_tight_size_bound_and_texture_size_sizes_the_impostor(tmp_path):
    """The budget's candidates at LeafQuality × 1/256 grow leaves 16× longer: probes, never
    written, so --max-size does not refuse them (the fan palm, 8.4 m, with --max-size 20 and
    --triangles 3000 was refused for 24 m leaves it would not build). And --texture-size with
    --no-textures is not void: it sizes the impostor's atlas (2 × it, 16 px views at 128)."""
    from treegen_cli import api

    s = api.make(species_path("fan_palm"), tmp_path / "p.glb", max_size=20, triangles=3000, no_wind=True)
    assert 2700 <= s["lods"][0]["triangles"] <= 3000
    api.make(species_path("rush"), tmp_path / "r.glb", no_textures=True, texture_size=128, no_wind=True)
    assert json.loads((tmp_path / "r.glb.impostor.json").read_text())["cell_px"] == 16


def test_explicit_options_win_over_the_profile(tmp_path):
    """--fps 30 is the click default, yet typed it beats the profile's 15 (parameter source)."""
    s = _make_json(
        species_path("quaking_aspen"),
        "-o",
        tmp_path / "a.glb",
        "--profile",
        "mobile",
        "--fps",
        "30",
        "--joints",
        "12",
        "--lod-distances",
        "0,40",
        "--texture-size",
        "64",
    )
    assert s["keys"] == 6 * 30 + 1  # mobile's 6 s clip at the typed 30 fps
    assert s["joints"] == 12
    assert [r["distance_m"] for r in s["lods"]][:2] == [0.0, 40.0]  # then the impostor
    assert len(s["lods"]) == 3
    assert s["triangles"] <= 20_000
    from treegen_cli import api

    v = api.resolve({"profile": "web", "triangles": 30_000, "max_joints": 256}).values
    assert (v["triangles"], v["max_joints"], v["fps"]) == (30_000, 256, 24.0)


def test_a_profiles_gltf_compression_stays_with_gltf():
    """--profile web sets meshopt, a glTF encoding: a USD or OBJ output takes the rest of the
    profile and no compression (it was refused for a --compress nobody typed); typed, it is
    still refused for USD."""
    from treegen_cli import api
    from treegen_cli.errors import TreegenError

    for out in ("palm.usdz", "palm.usdc", "palm.obj"):
        v = api.resolve({"profile": "web"}, output=out).values
        assert (v["compress"], v["fps"]) == ("none", 24.0), out
    assert api.resolve({"profile": "web"}, output="palm.glb").values["compress"] == "meshopt"
    with pytest.raises(TreegenError, match=r"--compress meshopt is for .glb/.gltf only"):
        api.resolve({"profile": "web", "compress": "meshopt"}, output="palm.usdz")


def test_a_catalogues_profile_compresses_its_gltf_files_only(tmp_path):
    """A catalogue with the web profile and formats glb + usdc: the GLB is meshopt-compressed,
    the USD written plainly (it was refused: "entries[0].compress: meshopt is for glb/gltf
    only", a key nobody wrote); a typed compress is still refused for USD."""
    import json

    from click.testing import CliRunner

    from treegen_cli.cli import cli
    from treegen_cli.exchange.gltf_container import read_gltf

    cat = tmp_path / "c.json"
    defaults = {"profile": "web", "formats": ["glb", "usdc"], "duration": 1, "fps": 10}
    cat.write_text(json.dumps({"defaults": defaults, "entries": [{"species": str(species_path("rush"))}]}))
    res = CliRunner().invoke(cli, ["batch", str(cat), "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    g, _ = read_gltf(tmp_path / "out" / "rush_0.glb")
    assert "EXT_meshopt_compression" in g["extensionsUsed"] and (tmp_path / "out" / "rush_0.usdc").is_file()
    cat.write_text(
        json.dumps({"defaults": {**defaults, "compress": "meshopt"}, "entries": [{"species": "rush"}]})
    )
    res = CliRunner().invoke(cli, ["batch", str(cat), "-o", str(tmp_path / "out2"), "--dry-run"])
    assert res.exit_code != 0 and "defaults.compress: meshopt is for glb/gltf only" in str(res.exception)


def test_joints_is_max_joints():
    from treegen_cli import api
    from treegen_cli.errors import TreegenError

    a = api.resolve({"joints": 40})
    assert a.values["max_joints"] == 40 and a.options == api.resolve({"max_joints": 40}).options
    with pytest.raises(TreegenError, match=r"^--joints 40 and --max-joints 30: .*give one of them$"):
        api.resolve({"joints": 40, "max_joints": 30})
    with pytest.raises(TreegenError, match=r"^--triangles 0: .*\[1, 100000000\]$"):
        api.resolve({"triangles": 0})
    with pytest.raises(TreegenError, match=r"^--profile 'phone': use one of"):
        api.resolve({"profile": "phone"})


def test_catalogue_accepts_a_profile(tmp_path):
    from treegen_cli.batch import parse_catalogue
    from treegen_cli.errors import TreegenError

    data = {"defaults": {"profile": "mobile"}, "entries": [{"species": str(species_path("rush")), "fps": 10}]}
    cat = parse_catalogue(data, tmp_path / "c.json")
    (r,) = cat.resolved.values()
    assert (r.values["triangles"], r.values["max_joints"], r.values["fps"]) == (20_000, 64, 10.0)
    assert r.options.budget.triangles == 20_000
    with pytest.raises(TreegenError, match=r"entries\[0\]\.profile"):
        parse_catalogue(
            {"entries": [{"species": str(species_path("rush")), "profile": "tv"}]}, tmp_path / "c.json"
        )


def test_readme_profile_table_is_the_module():
    from treegen_cli.profiles import markdown_table

    assert markdown_table() in (ROOT / "README.md").read_text("utf-8")
