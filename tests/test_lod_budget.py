"""Geometric LODs: triangle budgets, coverage-true leaf thinning, and the pops a viewer sees at
each switch (rendered with the project's renderer at the switch size).

Assets are built once per species without wind (the geometry is what is tested here).
"""

from __future__ import annotations

from functools import lru_cache

from dataclasses import replace

import numpy as np
import pytest

from conftest import SPECIES, grown, species_path
from treegen_cli.api import resolve
from treegen_cli.lod import LodOptions, pixel_size
from treegen_cli.lod_budget import TRIANGLE_CARD_PX, TRIANGLE_CARDS_FROM, bark_triangles, capped_sides
from treegen_cli.lod_leaves import prune_stems, stratified_pick, thin_leaves
from treegen_cli.mesh import MESH_DEFAULTS, build_mesh
from treegen_cli.params import load_params
from treegen_cli.pipeline import MakeOptions, build_asset
from treegen_cli.rig import build_rig

FRACTIONS = LodOptions().triangles  # (1, 0.5, 0.15, 0.05)
RENDER_PX = 384  # longest image side: leaves still span a pixel or more at every switch
COVERAGE_TOL = 0.05  # issue 13: covered area within ±5 % at every switch
IOU_TARGET = 0.9  # issue 13: silhouette IoU at least this at every switch
# Measured per species (worst switch, RENDER_PX, the view below, 6 × 6 samples a pixel;
# bench/lod_pop_bench.py --views 1 --max-px 384): (covered area off by at most, IoU at least),
# a regression guard a little below what the LODs reach where the target is not met (None:
# the target itself). Cover is within ±5 % for every species in this view. IoU ≥ 0.9 at
# every switch for the fir, the tupelo, the oak, the desert bush, the larch, the aspen, the
# rush, the sassafras, the tamarack and the willow; 0.87-0.89 for the cottonwood and the
# poplar; 0.74-0.82 for the palms and shave grass: at the
# far switches each kept leaf stands for several and the crown reads blotchy at the 3-pixel
# scale (the XOR of two LODs is speckle all over the crown, not its edge or trunk). What moved
# it: gathering kept leaves to the middle of the leaves they stand for (median +0.008) and
# triangle cards from LOD2 on (twice the leaves for the triangles: +0.03 to +0.05 where
# blades are a few pixels; the palms' fronds are too big for them), far LODs' few-sided
# stems drawn as wide as LOD0's (mesh.girth: rush 0.874 -> 0.926, desert bush +0.031, fan
# palm +0.021, larch +0.016), far twigs under 2 px drawn as crossed ribbons (4 triangles a
# segment for a tube's 6: oak 0.899 -> 0.904, larch 0.892 -> 0.902, desert bush 0.881 ->
# 0.901, shave grass 0.708 -> 0.744; poplar 0.882 -> 0.875); which leaves are kept
# moves it by the picking seed's ±0.013; leaf-cluster cards reached 0.9 for the aspen only
# (bench/lod_cards_bench.py). Shave grass, leafless, keeps part of its whorls' branches (as
# cones, spread over every whorl's sides, thickened) at 50, 15 and 5 % of the triangles.
MEASURED = {
    "balsam_fir": (None, None),
    "black_tupelo": (None, None),
    "ca_black_oak": (None, None),
    "desert_bush": (None, None),
    "eastern_cottonwood": (None, 0.88),
    "european_larch": (None, None),
    "fan_palm": (None, 0.80),
    "lombardy_poplar": (None, 0.87),
    "palm": (None, 0.80),
    "quaking_aspen": (None, None),
    "rush": (None, None),
    "sassafras": (None, None),
    "shave_grass": (None, 0.73),
    "tamarack": (None, None),
    "weeping_willow": (None, None),
}


@lru_cache(maxsize=None)
def _asset(name: str, **options):
    job = resolve(dict(no_wind=True, texture_size=128, **options))
    asset, _ = build_asset(load_params(species_path(name)), 0, job.options)
    return asset


def _within_lod0(asset, tol: float = 1e-3) -> None:
    """Every geometric LOD's leaves inside LOD0's box: enlarged blades fitted into it, so a
    LOD never grows the tree's outline at its switch (the fan palm's fronds reached 0.3 m,
    about 19 px, past LOD0's; a tiny budget's leaves poked metres out of the crown)."""
    box = np.concatenate([np.asarray(p.positions) for p in asset.lods[0].primitives if len(p.positions)])
    lo, hi = box.min(0) - tol, box.max(0) + tol
    for k, lod in enumerate(asset.lods[1:], 1):
        if lod.impostor is not None:
            continue
        for p in lod.primitives:
            if p.name == "leaves" and len(p.positions):
                x = np.asarray(p.positions)
                assert (x >= lo).all() and (x <= hi).all(), (k, x.min(0) - lo, hi - x.max(0))


def test_far_lods_stay_inside_lod0s_box():
    _within_lod0(_asset("fan_palm"))


def _bounds(lod) -> np.ndarray:
    """The rest-pose max corner of a LOD's geometry."""
    return np.concatenate([np.asarray(p.positions) for p in lod.primitives if len(p.positions)]).max(0)


def _tris(lod, name=None) -> int:
    return sum(len(p.indices) // 3 for p in lod.primitives if name is None or p.name == name)


@pytest.mark.parametrize("species", SPECIES)
def test_triangle_budgets(species):
    """Every LOD within its fraction of LOD0's triangles (the farthest ≤ 5 %), never more than
    the LOD before it; leaves skinned to joints of the LOD's own rig."""
    asset = _asset(species)
    *geometric, impostor = asset.lods
    assert impostor.impostor is not None and _tris(impostor) <= 0.05 * _tris(asset.lods[0])
    asset = replace(asset, lods=geometric)
    tris = [_tris(lod) for lod in asset.lods]
    assert len(tris) == 4
    for k, t in enumerate(tris):
        assert t <= FRACTIONS[k] * tris[0], (k, tris)
    assert tris == sorted(tris, reverse=True)
    for lod in asset.lods:
        for p in lod.primitives:
            assert int(np.asarray(p.joints).max()) < len(lod.skeleton.names)


@pytest.mark.parametrize("name", ["barley", "wheat"])
def test_stalks_over_the_bark_share_coarsen_until_the_lod_fits(name, monkeypatch):
    """Arbaro's barley (19 stalks, 2.8 mm) and wheat (49): their stalks alone took more than
    the bark's share of LOD2's and LOD3's budgets, drawn two rings a segment with nodes 1 px
    off their chords (barley's LOD3 2,043 triangles for 727). Where they still do after that,
    they now take one ring a segment and drop nodes up to MAX_TRUNK_TOL_PX off LOD0's stalk
    (measured on every node of it): every LOD is within its budget; LOD1, whose stalks fit
    once coarsened by a pixel, keeps two rings."""
    from pathlib import Path

    import treegen_cli.lod_budget as lod_budget
    from treegen_cli.generate import generate

    plans = []
    real = lod_budget.plan_lod

    def record(*args, **kwargs):
        plans.append(real(*args, **kwargs))
        return plans[-1]

    monkeypatch.setattr(lod_budget, "plan_lod", record)
    job = resolve(dict(no_wind=True, texture_size=128, impostor=False))
    path = Path(__file__).parent / "fixtures" / "arbaro" / f"{name}.xml"
    asset, _ = build_asset(load_params(path), 0, job.options)
    tris = [_tris(lod) for lod in asset.lods]
    for k, t in enumerate(tris):
        assert t <= FRACTIONS[k] * tris[0], (k, tris)
    rings = [plan.mesh.rings_per_segment for plan in plans]
    assert rings[0] != (1,) and rings[-1] == (1,), rings

    lod0 = generate(load_params(path), 0)
    stalk = np.flatnonzero(lod0.stem_level[lod0.node_stem] == 0)  # LOD0's stalks' nodes
    for k, plan in enumerate(plans, start=1):
        t = plan.tree
        kept = np.sort(t.lod0_nodes[t.stem_level[t.node_stem] == 0])  # each stalk's ends among them
        at = np.clip(np.searchsorted(kept, stalk, side="right") - 1, 0, kept.size - 2)
        a, c = lod0.node_pos[kept[at]], lod0.node_pos[kept[at + 1]]
        p = lod0.node_pos[stalk]
        d = c - a
        u = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-30), 0, 1)
        off = np.linalg.norm(a + u[:, None] * d - p, axis=1)
        off[np.isin(stalk, kept)] = 0.0  # (a stalk's last node: the next chord is another's)
        px = pixel_size(asset.lods[k].distance, LodOptions())
        assert off.max() <= lod_budget.MAX_TRUNK_TOL_PX * px, (k, off.max() / px)


def test_leaves_cover_what_the_kept_branches_cannot(monkeypatch):
    """Arbaro's barley: its LOD3 keeps 19 cones for the 665 awns of its ears, which show twice
    what its stalks do. Thickened as far as they go, the cones covered 78 % of what LOD0
    covers there (lod_cover's estimate; a third of the cover lost on screen at the switch).
    The leaves now stand in for the rest (lod_factors.STEMS_REACH)."""
    from pathlib import Path

    import treegen_cli.lod_budget as lod_budget
    from treegen_cli.lod_cover import Grid, tree_cover
    from treegen_cli.mesh import stem_sides

    ratios = []
    real = lod_budget.plan_lod

    def record(tree, bark0, leaf0, budget, mesh, px, mesh0=None, *args, **kwargs):
        plan = real(tree, bark0, leaf0, budget, mesh, px, mesh0, *args, **kwargs)
        grid = Grid.around(tree, px)
        full = tree_cover(tree, grid, stem_sides(tree, mesh0 or mesh))
        ratios.append(tree_cover(plan.tree, grid, stem_sides(plan.tree, plan.mesh or mesh)) / full)
        return plan

    monkeypatch.setattr(lod_budget, "plan_lod", record)
    job = resolve(dict(no_wind=True, texture_size=128, impostor=False))
    build_asset(load_params(Path(__file__).parent / "fixtures" / "arbaro" / "barley.xml"), 0, job.options)
    assert min(ratios) >= 0.95, ratios


@pytest.mark.parametrize("species", ["quaking_aspen", "fan_palm"])
def test_far_lods_draw_triangle_cards_where_blades_are_a_few_pixels(species):
    """A LOD from TRIANGLE_CARDS_FROM on whose switch shows LOD0's median blade at most
    TRIANGLE_CARD_PX long draws one triangle a leaf (its budget then holds about twice the
    leaves), the others cards: the aspen from its second LOD on, the fan palm (fronds a metre
    and a half long) never."""
    asset = _asset(species)
    lod0 = [p for p in asset.lods[0].primitives if p.name == "leaves"][0]
    quads = lod0.positions.reshape(-1, 4, 3)
    blade = float(np.median(np.linalg.norm(quads[:, 2] - quads[:, 0], axis=1)))
    drawn = []
    for k, lod in enumerate(asset.lods[1:], start=1):
        if lod.impostor is not None:
            continue
        leaves = [p for p in lod.primitives if p.name == "leaves"][0]
        per_leaf = len(leaves.positions) // (len(leaves.indices) // 3)  # 2 cards: 4 / 2 = 2
        triangle = (
            k >= TRIANGLE_CARDS_FROM and blade / pixel_size(lod.distance, LodOptions()) <= TRIANGLE_CARD_PX
        )
        assert per_leaf == (3 if triangle else 2), (lod.distance, per_leaf)
        drawn.append(triangle)
    assert drawn == ([False, True, True] if species == "quaking_aspen" else [False] * 3)


def test_triangle_card_blades_carry_the_blade_share_inside_the_triangle():
    """The cover estimator's blades drawn as triangle cards: every sample inside the triangle
    card, together carrying triangle_share of what the card's samples carry, so a LOD of
    triangle cards grows its leaves by what the triangle cuts off."""
    from treegen_cli.leafshapes import in_triangle_card, triangle_share
    from treegen_cli.lod_cover import Blades

    tree = grown("quaking_aspen")
    card, tri = Blades(tree, 0.01, 0.25), Blades(tree, 0.01, 0.25, triangle=True)
    assert np.all(in_triangle_card(tri.t, tri.s + 0.5)) and 0.4 < tri.s.size / card.s.size < 0.6
    share, _ = triangle_share(int(tree.params.leaf_shape))
    total = lambda b: b.seen.sum(axis=1) * b.s.size  # noqa: E731  (per view)
    np.testing.assert_allclose(total(tri), share * total(card), rtol=1e-9)


def test_triangle_blades_draw_the_blades_area_where_the_blade_was():
    """Sized and placed for triangle cards, a blade's drawn part (triangle_share of it, whose
    centre lies dy lengths from the card's middle) has the blade's area and sits where the
    blade did, in the blade's proportions."""
    from treegen_cli.leafshapes import triangle_share
    from treegen_cli.lod_budget import triangle_blades

    tree = grown("quaking_aspen")  # elliptic blades: their centre is the card's middle
    share, dy = triangle_share(int(tree.params.leaf_shape))
    t = triangle_blades(tree)
    np.testing.assert_allclose(share * t.leaf_area, tree.leaf_area, rtol=1e-9)
    np.testing.assert_allclose(
        t.leaf_size[:, 0] / t.leaf_size[:, 1], tree.leaf_size[:, 0] / tree.leaf_size[:, 1]
    )
    drawn = t.leaf_middle + (dy * t.leaf_size[:, 0])[:, None] * t.leaf_frame[:, :, 1]
    np.testing.assert_allclose(drawn, tree.leaf_middle, atol=1e-9)


def test_untextured_or_artist_leaves_keep_cards_in_every_lod(tmp_path):
    """Triangle cards only over the generated atlas, whose alpha is the outline
    triangle_share measures: untextured leaves (opaque cards) and an artist's image keep
    cards in every LOD, so their LODs cover alike."""
    from PIL import Image

    png = tmp_path / "leaf.png"
    img = Image.new("RGBA", (32, 32), (40, 120, 30, 255))
    img.putpixel((0, 0), (0, 0, 0, 0))  # (an opaque leaf image is refused)
    img.save(png)
    for options in (dict(no_textures=True), dict(leaf_texture=str(png))):
        asset = _asset("quaking_aspen", **options)
        for lod in asset.lods:
            if lod.impostor is None:
                leaves = [p for p in lod.primitives if p.name == "leaves"][0]
                assert len(leaves.positions) == 2 * (len(leaves.indices) // 3), options


def test_triangles_never_rise_whatever_the_options():
    """--sides below the LOD table: counts still fall LOD by LOD. Budgets that rise, percentages
    typed for fractions or an empty value are refused by name (--lod-triangles 0.5,0.6 wrote
    a LOD2 of 23,347 triangles, --lod-screen 50,25,10 put LOD3 at 2.9 m)."""
    from treegen_cli.errors import TreegenError

    asset = _asset("quaking_aspen", sides="5,3", lod_triangles="0.6,0.3,0.05")
    tris = [_tris(lod) for lod in asset.lods]
    assert tris == sorted(tris, reverse=True) and tris[1] <= 0.6 * tris[0], tris
    assert capped_sides((8, 6, 4, 3), (5, 3)) == (5, 3, 3, 3)
    refused = {
        "lod_triangles": ("0.5,0.6", "none above the one before"),
        "lod_screen": ("50,25,10", r"\(not percentages\), each in \[0\.0001, 4\]"),
    }
    for key, (value, message) in refused.items():
        flag = "--" + key.replace("_", "-")
        with pytest.raises(TreegenError, match=rf"^{flag} '?{value}'?: .*{message}"):
            resolve({key: value})
    for key in ("lod_screen", "lod_triangles", "lod_distances", "sides"):
        with pytest.raises(TreegenError, match=r"'0\.5,,0\.1': an empty value between commas; expected"):
            resolve({key: "0.5,,0.1"})


def test_tiny_budgets_keep_blades_within_the_crown_and_say_they_are_exceeded(tmp_path):
    """--lod-triangles 0.9,0.0001 (8 triangles for LOD2) drew LOD2 as the trunk and one leaf
    grown to stand for the crown: a card 883 m wide. A budget the trunk fills keeps the leaves'
    share of it (none at a budget of 0); no blade grows past MAX_BLADE_SHARE of the crown, nor
    out of LOD0's box; make's summary
    gives each LOD's budget and prints the LODs over theirs."""
    from click.testing import CliRunner

    from treegen_cli.cli import cli
    from treegen_cli.lod_budget import MAX_BLADE_SHARE

    crown = None
    for table, leafless in (("0.9,0.0001", (3,)), ("0.9,0.002", (3,))):
        asset = _asset("quaking_aspen", lod_triangles=table, impostor=False)
        leaves0 = np.concatenate([p.positions for p in asset.lods[0].primitives if p.name == "leaves"])
        crown = float(np.ptp(leaves0, axis=0).max())
        for k, lod in enumerate(asset.lods[1:], 1):
            leaves = [p for p in lod.primitives if p.name == "leaves" and len(p.indices)]
            assert bool(leaves) == (k not in leafless), (table, k)
            for p in leaves:  # a blade's corners are at most its length + width apart
                tri = np.asarray(p.positions)[np.asarray(p.indices).reshape(-1, 3)]
                span = np.linalg.norm(tri[:, :, None] - tri[:, None, :], axis=-1).max()
                assert span <= 2.0 * MAX_BLADE_SHARE * crown * 1.001, (table, k, span, crown)
        _within_lod0(asset)
    # the impostor is drawn from the last LOD with leaves (LOD1 here), not from a bare trunk
    from treegen_cli.render_gl import egl_available

    if not egl_available():
        pytest.fail("no headless OpenGL (EGL) context: the impostor cannot be rendered here")
    tiny = _asset("quaking_aspen", lod_triangles="0.9,0.0001").lods[-1].impostor
    assert tiny is not None and np.allclose(
        tiny.bounds[1], _bounds(_asset("quaking_aspen", lod_triangles="0.9,0.0001").lods[1])
    )
    species = str(species_path("quaking_aspen"))
    res = CliRunner().invoke(
        cli, ["make", species, "-o", str(tmp_path / "a.glb"), "--lod-triangles", "0.9,0.0001", "--json"]
    )
    assert res.exit_code == 0, res.output
    import json

    rows = json.loads(res.output)["lods"]
    assert [r.get("budget") for r in rows[:3]] == [
        None,
        int(0.9 * rows[0]["triangles"]),
        int(1e-4 * rows[0]["triangles"]),
    ]
    assert rows[2]["triangles"] > rows[2]["budget"] and rows[-1]["impostor"] and rows[-1]["budget"] is None
    res = CliRunner().invoke(
        cli, ["make", species, "-o", str(tmp_path / "b.glb"), "--lod-triangles", "0.9,0.0001"]
    )
    assert f"over its budget of {rows[2]['budget']:,}: its trunks alone take more" in res.output


def test_trunks_under_a_pixel_coarsen_as_branches_do():
    """A grass's stalks are trunks (Arbaro's wheat: 49 of them, 2.8 mm): under a pixel wide at a
    far switch their nodes are dropped within the chord tolerance, as a branch's are; kept
    whole, LOD3 (10.8 m) drew 7,962 triangles for a budget of 2,361. At LOD2 (4.3 m) they span
    a pixel and keep every node, as trunks do."""
    from pathlib import Path

    from treegen_cli.generate import generate
    from treegen_cli.lod_budget import THIN_TRUNK_PX

    params = load_params(Path(__file__).parent / "fixtures" / "arbaro" / "wheat.xml")
    job = resolve(dict(no_wind=True, impostor=False, texture_size=128))
    tree = generate(params, 0)
    asset, _ = build_asset(params, 0, job.options, tree=tree)
    tris = [sum(len(p.indices) // 3 for p in lod.primitives) for lod in asset.lods]
    trunk = 2.0 * float(tree.stem_radius[tree.stem_level == 0].max())
    opts = job.options.lod
    assert trunk >= THIN_TRUNK_PX * pixel_size(asset.lods[2].distance, opts)  # LOD2: trunks whole
    assert trunk < THIN_TRUNK_PX * pixel_size(asset.lods[3].distance, opts)  # LOD3: coarsened
    assert tris[3] <= 1.25 * FRACTIONS[3] * tris[0], tris  # near its 5 % (was 17 %)


def _drawn_leaves(lod) -> int:
    """Leaves a LOD's mesh draws: cards by their corners, outline blades as connected pieces."""
    from treegen_cli.impostor_shading import leaf_ids
    from treegen_cli.leafshapes import card_corners

    count = 0
    for p in lod.primitives:
        if p.name == "leaves" and len(p.positions):
            corners = card_corners(len(p.positions), len(p.indices))
            count += (
                len(p.positions) // corners
                if corners
                else int(leaf_ids(p.indices, len(p.positions)).max()) + 1
            )
    return count


def test_no_lod_keeps_more_leaves_than_the_one_before():
    """Arbaro's wheat at 30 / 15 / 5 %: LOD1 keeps 515 of its 1,715 leaves as cards, and
    LOD2's triangle cards (a triangle a leaf) would fit more in its budget, so the crown would
    thin at one switch and fill back at the next (at the default budgets, before far twigs
    were drawn as ribbons, LOD1 kept 857 and LOD2 all 1,715 again: IoU 0.845 at switch 2).
    Capped at LOD1's, LOD2 keeps the same leaves, and every LOD's leaves are among the ones
    before (nested)."""
    from pathlib import Path

    from treegen_cli.render_gl import egl_available
    from treegen_cli.silhouette import lod_pops

    params = load_params(Path(__file__).parent / "fixtures" / "arbaro" / "wheat.xml")
    job = resolve(dict(no_wind=True, impostor=False, texture_size=128, lod_triangles=(0.3, 0.15, 0.05)))
    asset, _ = build_asset(params, 0, job.options)
    counts = [_drawn_leaves(lod) for lod in asset.lods]
    assert counts[1] < counts[0] and counts == sorted(counts, reverse=True), counts
    if not egl_available():
        pytest.fail("no headless OpenGL (EGL) context: the renderer cannot run here")
    pop = lod_pops(asset, LodOptions(), views=(-90.0,), max_px=RENDER_PX)[1]
    assert pop.iou >= 0.87 and abs(pop.coverage - 1.0) <= COVERAGE_TOL, pop


def test_leaves_drawn_as_their_outline_count_as_leaves_across_lods():
    """`--leaf-geometry shape` draws each blade as its outline (the aspen's: 8 triangles), not a
    card: the LOD-to-LOD leaf cap holds for them too (counting the cap by card corners divided
    by zero and `make` died with a traceback)."""
    job = resolve(dict(no_wind=True, impostor=False, texture_size=128, leaf_geometry="shape"))
    asset, _ = build_asset(
        load_params(species_path("quaking_aspen")), 0, job.options, tree=grown("quaking_aspen")
    )
    counts = [_drawn_leaves(lod) for lod in asset.lods]
    assert counts[0] == grown("quaking_aspen").n_leaves and counts == sorted(counts, reverse=True), counts


def test_trunks_over_the_bark_budget_coarsen_whatever_their_width(monkeypatch):
    """Arbaro's barley: 19 stalks a pixel wide or more at LOD1 and LOD2 took the whole budget
    kept whole (LOD1 11,893 triangles for 7,277, LOD2 11,427 for 2,183), so every ear's awns
    were dropped and its grains grown. Trunks whose bark alone exceeds the bark's share are
    coarsened within the chord tolerance: LOD1 meets its budget and keeps branches (the awns)."""
    from pathlib import Path

    import treegen_cli.pipeline as pipeline

    built = {}
    real = pipeline.lod_tree

    def record(tree, k, *args, **kwargs):
        out = real(tree, k, *args, **kwargs)
        built[k] = out[0]
        return out

    monkeypatch.setattr(pipeline, "lod_tree", record)
    params = load_params(Path(__file__).parent / "fixtures" / "arbaro" / "barley.xml")
    job = resolve(dict(no_wind=True, impostor=False, texture_size=128))
    asset, tree = build_asset(params, 0, job.options)
    tris = [sum(len(p.indices) // 3 for p in lod.primitives) for lod in asset.lods]
    assert tris[1] <= FRACTIONS[1] * tris[0] and tris[2] <= 1.25 * FRACTIONS[2] * tris[0], tris
    awns = int((tree.stem_level > 0).sum())
    assert (built[1].stem_level > 0).sum() > 0.5 * awns, (int((built[1].stem_level > 0).sum()), awns)


def test_more_distances_than_budgets_step_on_by_the_last_ratio():
    """Five distances and the default 0.5, 0.15, 0.05: LOD4 gets a third of LOD3's budget (the
    last value repeated made it a copy of LOD3, 4,176 triangles each on the aspen)."""
    from treegen_cli.lod_budget import triangle_fraction

    table = LodOptions().triangles
    assert [round(triangle_fraction(table, k), 6) for k in range(6)] == [
        1,
        0.5,
        0.15,
        0.05,
        0.016667,
        0.005556,
    ]
    assert triangle_fraction((1.0, 0.4), 3) == pytest.approx(0.064)
    assert triangle_fraction((1.0,), 2) == 1.0
    asset = _asset("quaking_aspen", lod_distances="0,10,20,30,40", impostor=False)
    tris = [_tris(lod) for lod in asset.lods]
    assert len(tris) == 5 and tris[4] <= tris[0] * 0.05 / 3 < tris[3], tris


def test_lod_triangles_option_is_checked():
    from treegen_cli.errors import TreegenError

    for bad in ("0.5,0", "1.5", "0.5,x"):
        with pytest.raises(TreegenError, match="--lod-triangles"):
            resolve(dict(lod_triangles=bad))
    assert resolve(dict(lod_triangles="0.4")).options.lod.triangles == (1.0, 0.4)


def test_bark_estimate_bounds_the_mesh():
    """The planner's per-stem bark count is an upper bound within a few % of the real mesh."""
    for name in ("black_tupelo", "shave_grass", "ca_black_oak"):
        tree = grown(name)
        est = int(bark_triangles(tree, MESH_DEFAULTS).sum())
        bark = build_mesh(tree, build_rig(tree), MESH_DEFAULTS)[0]
        real = len(bark.indices) // 3
        assert real <= est <= 1.05 * real, (name, real, est)


def test_stratified_pick_spreads_like_the_full_set():
    """Each octant of the crown keeps its share of the leaves (a leaf subset along the main
    branches would not); exact count, no repeats, deterministic."""
    tree = grown("quaking_aspen")
    pts = tree.leaf_pos
    n = tree.n_leaves // 8
    pick = stratified_pick(pts, n, 3)
    assert pick.size == n and np.unique(pick).size == n
    assert np.array_equal(pick, stratified_pick(pts, n, 3))
    mid = np.median(pts, axis=0)
    octant = lambda p: ((p > mid) * [1, 2, 4]).sum(axis=1)  # noqa: E731
    full = np.bincount(octant(pts), minlength=8) / len(pts)
    kept = np.bincount(octant(pts[pick]), minlength=8) / n
    assert np.abs(kept - full).max() < 0.01


def test_gathered_leaves_sit_among_the_leaves_they_stand_for():
    """A thinned LOD's kept leaves, moved to the middle of the leaves nearest them, are
    nearer the full crown's leaves than where they grew (a Lloyd step: the area-weighted
    squared distance from each leaf to its nearest kept one falls); frames and sizes kept."""
    from scipy.spatial import cKDTree

    tree = grown("quaking_aspen")
    n = tree.n_leaves // 8
    pick = stratified_pick(tree.leaf_pos, n, tree.seed)
    thin = thin_leaves(tree, n, 1.0)
    assert np.array_equal(thin.leaf_frame, tree.leaf_frame[pick])
    assert np.array_equal(thin.leaf_size, tree.leaf_size[pick])
    mids = tree.leaf_middle

    def spread(kept):
        return float(np.sum(tree.leaf_area * cKDTree(kept).query(mids)[0] ** 2))

    before, after = spread(mids[pick]), spread(thin.leaf_middle)
    assert after < 0.8 * before, (before, after)
    assert np.array_equal(thin_leaves(tree, tree.n_leaves, 1.0).leaf_pos, tree.leaf_pos)


def test_pruned_stems_keep_their_leaves_in_place():
    """Dropping the finest level keeps every leaf where it was, hung from a node of a kept
    stem where its branch attached; node and stem tables stay consistent; thinning keeps area."""
    tree = grown("quaking_aspen")
    keep = tree.stem_level < tree.stem_level.max()
    lod = prune_stems(tree, keep)
    assert lod.n_leaves == tree.n_leaves and np.array_equal(lod.leaf_pos, tree.leaf_pos)
    assert lod.n_stems == int(keep.sum()) and lod.n_nodes == int(keep[tree.node_stem].sum())
    assert np.array_equal(lod.node_stem[lod.leaf_node], lod.leaf_stem)
    starts = lod.stem_node_start
    assert np.array_equal(lod.node_stem[starts], np.arange(lod.n_stems))
    rig = build_rig(lod)
    assert rig.leaf_joint.max() < len(rig.skeleton.names)
    thin = thin_leaves(lod, lod.n_leaves // 4, 4.0)
    assert thin.leaf_area.sum() == pytest.approx(lod.leaf_area.sum(), rel=0.05)


def test_coarsened_branches_stay_within_the_tolerance():
    """coarsen_nodes drops branch nodes only where the kept polyline passes within `tol` of
    them: every dropped node lies within tol of its stem's new polyline, trunks keep all their
    nodes, tables stay consistent (leaves and child stems on kept nodes of their own stem),
    and the bark it saves is real."""
    from treegen_cli.lod_nodes import coarsen_nodes

    tree = grown("european_larch")
    tol = 0.02
    lod = coarsen_nodes(tree, tol)
    assert lod.n_nodes < 0.8 * tree.n_nodes and lod.n_stems == tree.n_stems
    trunk = tree.stem_level == 0
    assert np.array_equal(lod.stem_node_count[trunk], tree.stem_node_count[trunk])
    assert np.array_equal(lod.node_stem[lod.stem_node_start], np.arange(lod.n_stems))
    assert np.array_equal(lod.node_stem[lod.leaf_node], lod.leaf_stem)
    child = lod.stem_parent >= 0
    assert np.array_equal(lod.node_stem[lod.stem_parent_node[child]], lod.stem_parent[child])
    # each dropped node within tol of its stem's coarse polyline
    kept = {tuple(p) for p in lod.node_pos}
    gone = np.array([i for i, p in enumerate(tree.node_pos) if tuple(p) not in kept])
    assert gone.size
    for i in gone[:: max(1, gone.size // 400)]:
        s = tree.node_stem[i]
        q = lod.node_pos[lod.stem_node_start[s] : lod.stem_node_start[s] + lod.stem_node_count[s]]
        a, b = q[:-1], q[1:]
        d = b - a
        t = np.clip(np.einsum("ij,ij->i", tree.node_pos[i] - a, d) / np.einsum("ij,ij->i", d, d), 0, 1)
        dist = np.linalg.norm(a + t[:, None] * d - tree.node_pos[i], axis=1).min()
        assert dist <= tol * (1 + 1e-9), (i, dist)
    assert bark_triangles(lod, MESH_DEFAULTS).sum() < bark_triangles(tree, MESH_DEFAULTS).sum()
    assert build_rig(lod).leaf_joint.max() < len(build_rig(lod).skeleton.names)
    assert coarsen_nodes(tree, 0.0) is tree


def test_far_lods_keep_the_stems_their_leaves_hang_from(monkeypatch):
    """The fan palm's fronds sit at the end of petioles 1-2 m long. A LOD that cannot afford a
    petiole whole keeps it as a pointed cone from base to tip (lod_budget.floating,
    lod_nodes.stub_stems), so every leaf of every LOD is within GAP_PX pixels, at the LOD's
    switch, of the bark it is drawn with (dropped, the fronds floated round a bare trunk:
    56 px at LOD2, 24 px at LOD3). The stubs end in a point; the leaves keep their places and
    bind to kept nodes; a budget with no room for them gets none."""
    import treegen_cli.pipeline as pipeline
    from scipy.spatial import cKDTree

    from treegen_cli.lod_budget import GAP_PX

    built = []
    real = pipeline.lod_tree

    def record(tree, k, *args, **kwargs):
        out = real(tree, k, *args, **kwargs)
        built.append((k, out[0], args[-1]))
        return out

    monkeypatch.setattr(pipeline, "lod_tree", record)
    job = resolve(dict(no_wind=True, texture_size=128, impostor=False))
    build_asset(load_params(species_path("fan_palm")), 0, job.options, tree=grown("fan_palm"))
    stubs = []
    for k, t, at in built:
        px = pixel_size(at.distances[k], at)
        seg = np.flatnonzero(t.node_stem[:-1] == t.node_stem[1:])  # points along every segment
        p0, p1 = t.node_pos[seg], t.node_pos[seg + 1]
        n = np.maximum(1, np.ceil(np.linalg.norm(p1 - p0, axis=1) / (0.25 * px))).astype(int)
        w = np.repeat(np.arange(n.size), n)
        s = (np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)) / n[w]
        gap, _ = cKDTree(p0[w] + s[:, None] * (p1 - p0)[w]).query(t.leaf_pos)
        assert gap.max() <= GAP_PX * px, (k, gap.max() / px)
        assert np.array_equal(t.node_stem[t.leaf_node], t.leaf_stem)
        stubs.append(_pointed(t))
    assert stubs[1] > 0 and stubs[2] > 0  # LOD2 and LOD3 draw petioles as cones
    # a budget its trunk fills gets no stubs; its leaves keep their share of it (LOD3 at 0.05 %,
    # 4 triangles: at 0.2 % the trunk, coarsened to one ring a segment and 4 px off once it
    # alone exceeded the bark's share, left room for two cones; at 0.1 % for one stub drawn
    # as crossed ribbons, two triangles)
    built.clear()
    tight = resolve(dict(no_wind=True, texture_size=128, impostor=False, lod_triangles=(0.5, 0.05, 0.0005)))
    asset, _ = build_asset(load_params(species_path("fan_palm")), 0, tight.options, tree=grown("fan_palm"))
    assert _pointed(built[-1][1]) == 0
    assert sum(len(p.indices) // 3 for p in asset.lods[3].primitives if p.name == "leaves") > 0


def _pointed(tree) -> int:
    """Branches of a leafy LOD that end in a point: the stubs (only a leafless LOD points
    its twigs, lod_nodes.point_tips)."""
    tips = tree.stem_node_start + tree.stem_node_count - 1
    return int(((tree.stem_level > 0) & (tree.node_radius[tips] == 0.0)).sum())


@pytest.mark.parametrize("species", SPECIES)
def test_lod_switches_keep_cover(species):
    """Consecutive LODs rendered at the tree's size on screen at their switch (fov 60°, 1920
    px, the project's renderer, alpha-tested leaves): covered area within ±5 % and silhouette
    IoU ≥ 0.9 (issue 13), or no worse than measured (MEASURED) where that is not reached."""
    from treegen_cli.render_gl import egl_available
    from treegen_cli.silhouette import lod_pops

    if not egl_available():
        pytest.fail("no headless OpenGL (EGL) context: the renderer cannot run here")
    asset = _asset(species)
    asset = replace(asset, lods=[lod for lod in asset.lods if lod.impostor is None])  # (test_impostor)
    cover_off, iou = MEASURED[species]
    for pop in lod_pops(asset, LodOptions(), views=(-90.0,), max_px=RENDER_PX):
        assert abs(pop.coverage - 1.0) <= (cover_off or COVERAGE_TOL), (species, pop)
        assert pop.iou >= (iou or IOU_TARGET), (species, pop)


def test_leaves_do_not_stand_in_for_twigs_that_outweigh_them(monkeypatch):
    """The desert bush's far LODs drop twigs showing 8 to 19 times its leaves' area: its kept
    branches thicken to cover their share and its leaves grow for the leaves only
    (lod_factors.STEM_STANDIN), so the bush stays bark-coloured. Grown for the twigs too, the
    leaves drew 6 and 14 times LOD0's leaf area (green cards round a bare bush); LOD1, which
    drops less than twice the leaves' area in twigs, still grows its leaves for them."""
    import treegen_cli.lod_budget as lod_budget
    from treegen_cli.pipeline import _leaf_area

    asset = _asset("desert_bush")
    share = [_leaf_area(lod) / _leaf_area(asset.lods[0]) for lod in asset.lods if lod.impostor is None]
    assert share[1] > 2.0 and max(share[2:]) < 1.5, share
    radii = []  # each LOD's branch radius factor, as planned
    real = lod_budget.cover_factors

    def record(*args, **kwargs):
        out = real(*args, **kwargs)
        radii.append(out[1])
        return out

    monkeypatch.setattr(lod_budget, "cover_factors", record)
    job = resolve(dict(no_wind=True, texture_size=128, impostor=False))
    build_asset(load_params(species_path("desert_bush")), 0, job.options, tree=grown("desert_bush"))
    assert radii[0] == 1.0 and min(radii[1:]) > 1.0, radii  # LOD1: leaves; LOD2, LOD3: branches


def test_default_options_build_the_planned_tree():
    """MakeOptions' defaults and resolve()'s agree on the budgets (one source of defaults)."""
    assert MakeOptions().lod.triangles == resolve({}).options.lod.triangles


def test_solve_factor_meets_the_target_or_stops_at_the_clamp():
    """lod_cover.solve_factor (secant from 1, Illinois once bracketed): a smooth cover is met
    within tolerance in a few calls; a target out of reach, or a cover that does not move,
    ends at the clamp on the far side; a cover that jumps past the target ends at the jump."""
    import math

    from treegen_cli.lod_cover import solve_factor

    calls = []

    def smooth(f):
        calls.append(f)
        return 1.0 - math.exp(-0.3 * f)

    target = 1.0 - math.exp(-0.3 * 2.7)
    f = solve_factor(smooth, target, 0.25, 8.0)
    assert abs(smooth(f) - target) <= 0.005 * target and len(calls) <= 7, (f, calls)
    assert solve_factor(lambda f: 0.1 * f, 5.0, 0.25, 4.0) == 4.0  # out of reach above
    assert solve_factor(lambda f: 0.1 * f, 0.001, 0.25, 4.0) == 0.25  # and below
    assert solve_factor(lambda f: 0.5, 0.7, 0.5, 32.0) == 32.0  # flat, short of the target
    assert solve_factor(lambda f: 0.5, 0.3, 0.5, 32.0) == 0.5  # flat, past it
    jump = solve_factor(lambda f: 0.2 if f < 3.0 else 0.9, 0.5, 0.25, 8.0)
    assert abs(jump - 3.0) < 0.3, jump
