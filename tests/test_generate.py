"""The Weber–Penn generator: formulas on hand-built cases, invariants on every species."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from treegen_cli.errors import TreegenError
from treegen_cli.generate import GenerateOptions, error_diffuse, estimate_counts, generate
from treegen_cli.params import LevelParams, default_params, load_params
from treegen_cli.shapes import flare_factor, shape_ratio, taper_radius

SPECIES = sorted((Path(__file__).parent.parent / "species").glob("*.txt"))


def _params(levels=2, **top):
    """A small deterministic species: no length/angle variation unless asked."""
    lv = [LevelParams(length=1.0, curve_res=4, branches=1)]
    lv.append(LevelParams(length=0.3, curve_res=3, down_angle=45, rotate=140, branches=12))
    lv.append(LevelParams(length=0.5, curve_res=2, down_angle=30, rotate=140, branches=6))
    lv.append(LevelParams(down_angle=40, rotate=90))
    lv += [LevelParams()] * (10 - len(lv))
    base = dict(
        name="hand",
        shape=4,
        base_size=0.3,
        scale=10.0,
        scale_v=0.0,
        levels=levels,
        ratio=0.02,
        ratio_power=1.2,
        leaves=0.0,
        leaf_scale=0.2,
        leaf_scale_x=0.5,
        flare=0.0,
        level=tuple(lv),
    )
    base.update(top)
    return dataclasses.replace(default_params(), **base)


def _level(p, n, **kw):
    lv = list(p.level)
    lv[n] = dataclasses.replace(lv[n], **kw)
    return dataclasses.replace(p, level=tuple(lv))


# ------------------------------------------------------------------- formulas


@pytest.mark.parametrize(
    "shape,r,expected",
    [
        (0, 0.5, 0.6),
        (1, 0.5, 1.0),
        (2, 1.0, 1.0),
        (3, 0.3, 1.0),
        (4, 0.0, 0.5),
        (5, 0.35, 0.5),
        (5, 0.85, 0.5),
        (6, 1.0, 0.2),
        (7, 0.0, 0.5),
        (7, 1.0, 0.5),
    ],
)
def test_shape_ratio_table(shape, r, expected):
    assert shape_ratio(shape, r) == pytest.approx(expected)


def test_envelope_is_zero_outside_and_peaks_at_one():
    r = np.array([-0.1, 0.0, 0.5, 1.0, 1.1])
    v = shape_ratio(8, r, 0.5, 0.5, 0.5)
    assert v[0] == 0 and v[-1] == 0 and v[2] == pytest.approx(1.0)
    # continuous at the peak for any PruneWidthPeak
    peak = 0.3
    below, above = shape_ratio(8, [0.7 - 1e-9, 0.7 + 1e-9], peak, 0.7, 1.3)
    assert below == pytest.approx(above, abs=1e-6)


def test_error_diffusion_tracks_running_sum():
    assert list(error_diffuse([0.4] * 5)) == [0, 1, 0, 1, 0]
    vals = np.random.default_rng(1).uniform(0, 3, 1000)
    counts = error_diffuse(vals)
    assert np.all(np.abs(np.cumsum(counts) - np.cumsum(vals)) <= 0.5 + 1e-9)


def test_taper_profiles():
    z = np.linspace(0, 10, 11)
    cone = taper_radius(1.0, 10.0, 1.0, z)
    assert cone[0] == 1.0 and cone[5] == pytest.approx(0.5) and cone[-1] > 0
    cylinder_ish = taper_radius(1.0, 10.0, 0.0, z)
    assert np.allclose(cylinder_ish, 1.0)
    half = taper_radius(1.0, 10.0, 0.5, z)
    assert half[-1] == pytest.approx(0.5)
    periodic = taper_radius(1.0, 10.0, 2.5, np.linspace(0, 10, 400))
    assert np.any(np.diff(periodic) > 0)  # beads: radius goes up again
    assert np.all(flare_factor(1.0, np.array([0.0, 0.125, 0.5])) == pytest.approx([1.99, 1.0, 1.0]))


def test_trunk_children_count_is_nbranches_and_above_base():
    p = _params(levels=2)
    t = generate(p, seed=3)
    kids = t.stem_level == 1
    assert kids.sum() == 12
    trunk_len = t.stem_length[0]
    assert np.all(t.stem_offset[kids] >= p.base_size * trunk_len - 1e-9)
    # level-1 length: L_parent · nLength · ShapeRatio(Shape, (L − offset)/(L − base))
    rel = (trunk_len - t.stem_offset[kids]) / (trunk_len * (1 - p.base_size))
    expected = trunk_len * 0.3 * shape_ratio(4, rel)
    assert np.allclose(t.stem_length[kids], expected)


def test_level2_counts_follow_the_length_formula():
    p = _params(levels=3)
    t = generate(p, seed=5)
    l1 = np.flatnonzero(t.stem_level == 1)
    per = p.level[2].branches * (0.2 + 0.8 * (t.stem_length[l1] / t.stem_length[0]) / p.level[1].length)
    assert (t.stem_level == 2).sum() == int(np.floor(per.sum() + 0.5))
    # every level-2 stem hangs on a level-1 stem; its length is nLength·(L_parent − 0.6·offset)
    l2 = t.stem_level == 2
    parents = t.stem_parent[l2]
    assert np.all(t.stem_level[parents] == 1)
    assert np.allclose(t.stem_length[l2], 0.5 * (t.stem_length[parents] - 0.6 * t.stem_offset[l2]))
    # radius: r_parent·(L/L_parent)^RatioPower, capped by the parent's radius there
    cap = t.stem_radius[parents] * (t.stem_length[l2] / t.stem_length[parents]) ** p.ratio_power
    node = t.stem_parent_node[l2]
    frac = (t.stem_offset[l2] - t.node_z[node]) / (t.node_z[node + 1] - t.node_z[node])
    at_attach = t.node_radius[node] + (t.node_radius[node + 1] - t.node_radius[node]) * frac
    assert np.allclose(t.stem_radius[l2], np.minimum(cap, at_attach))
    # a low RatioPower makes children as thick as their parent: the cap must bind
    fat = generate(dataclasses.replace(p, ratio_power=0.1), seed=5)
    l2 = fat.stem_level == 2
    node = fat.stem_parent_node[l2]
    frac = (fat.stem_offset[l2] - fat.node_z[node]) / (fat.node_z[node + 1] - fat.node_z[node])
    at_attach = fat.node_radius[node] + (fat.node_radius[node + 1] - fat.node_radius[node]) * frac
    assert np.any(np.isclose(fat.stem_radius[l2], at_attach))
    assert np.all(fat.stem_radius[l2] <= at_attach + 1e-12)


def test_leaf_counts_and_sizes():
    p = _params(levels=3, leaves=8.0, leaf_quality=1.0, leaf_distrib=4)
    t = generate(p, seed=2)
    last = np.flatnonzero(t.stem_level == 2)
    rel = t.stem_offset[last] / t.stem_length[t.stem_parent[last]]
    expected = np.floor(np.sum(8.0 * shape_ratio(4, rel)) + 0.5)
    assert t.n_leaves == expected
    assert np.allclose(t.leaf_size, [0.2, 0.1])
    assert np.all(t.stem_level[t.leaf_stem] == 2)


def test_leaf_quality_keeps_total_area():
    p = _params(levels=3, leaves=20.0)
    full = generate(p, seed=4)
    coarse = generate(p, seed=4, options=GenerateOptions(leaf_quality=0.25))
    assert coarse.n_leaves == pytest.approx(full.n_leaves * 0.25, rel=0.05)
    assert coarse.leaf_area.sum() == pytest.approx(full.leaf_area.sum(), rel=0.05)


def test_whorled_leaves_share_offsets():
    p = _params(levels=2, leaves=12.0)
    p = _level(p, 2, rotate=-120.0, rotate_v=0.0)  # 3 leaves per whorl
    t = generate(p, seed=1)
    assert t.n_leaves % 3 == 0
    # the three leaves of a group attach at the same node and offset: same stem, same node
    groups = t.leaf_node.reshape(-1, 3)
    assert np.all(groups == groups[:, :1])


def test_alternating_rotate_flips_sides():
    p = _level(_params(levels=2), 1, rotate=-120.0, rotate_v=0.0, down_angle=60)
    t = generate(p, seed=0)
    kids = np.flatnonzero(t.stem_level == 1)
    d = t.node_frame[t.stem_node_start[kids], :, 2][:, :2]
    ang = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    turn = (np.diff(ang) + 360) % 360
    # ±(180 + nRotate) = ±60 about the trunk: successive children turn by 240° then 120°
    assert np.allclose(turn[0::2], turn[0], atol=1e-6) and np.allclose(turn[1::2], turn[1], atol=1e-6)
    assert sorted([round(turn[0]), round(turn[1])]) == [120, 240]


def test_negative_down_angle_v_varies_along_parent():
    p = _level(_params(levels=2), 1, down_angle=60, down_angle_v=-50)
    t = generate(p, seed=0)
    kids = np.flatnonzero(t.stem_level == 1)
    d = t.node_frame[t.stem_node_start[kids], :, 2]
    down = np.degrees(np.arccos(np.clip(d[:, 2], -1, 1)))
    order = np.argsort(t.stem_offset[kids])
    # low branches droop more than high ones (60 + (−50)(1 − 2·ShapeRatio(0, rel)))
    assert down[order][0] > down[order][-1]


def test_base_splits_make_clones():
    p = _params(levels=1, base_splits=2)
    t = generate(p, seed=0)
    assert t.n_stems == 3 and t.stem_clone.sum() == 2
    clones = np.flatnonzero(t.stem_clone)
    # a clone starts on its parent's split node and continues its z
    for c in clones:
        first = t.stem_node_start[c]
        assert np.allclose(t.node_pos[first], t.node_pos[t.stem_parent_node[c]])
        assert t.node_z[first] == pytest.approx(t.node_z[t.stem_parent_node[c]])


def test_helix_for_negative_curve_v():
    p = _level(_params(levels=1), 0, curve_res=12, curve_v=-30.0)
    t = generate(p, seed=0)
    d = t.node_frame[1:-1, :, 2]
    tilt = np.degrees(np.arccos(np.clip(d[:, 2], -1, 1)))
    assert np.allclose(tilt, 30.0, atol=1e-6)  # constant angle to the axis
    heading = np.unwrap(np.arctan2(d[:, 1], d[:, 0]))
    assert np.all(np.diff(heading) > 0) or np.all(np.diff(heading) < 0)


def test_attraction_up_lifts_and_negative_droops():
    def mean_dir(a):
        p = _level(_params(levels=3, attraction_up=a), 2, curve_res=6, down_angle=80)
        t = generate(p, seed=0)
        tips = t.stem_node_start[t.stem_level == 2] + t.stem_node_count[t.stem_level == 2] - 1
        return t.node_frame[tips, :, 2][:, 2].mean()

    assert mean_dir(2.0) > mean_dir(0.0) > mean_dir(-2.0)


def test_pruning_keeps_stems_inside_the_envelope():
    from treegen_cli.generate.prune import inside_envelope

    p = _params(levels=3, prune_ratio=1.0, prune_width=0.3, prune_width_peak=0.5)
    t = generate(p, seed=0)
    loose = generate(dataclasses.replace(p, prune_ratio=0.0), seed=0)
    inside = inside_envelope(p, t.scale, t.node_pos[t.stem_level[t.node_stem] >= 1])
    inside_loose = inside_envelope(p, loose.scale, loose.node_pos[loose.stem_level[loose.node_stem] >= 1])
    assert inside.mean() > inside_loose.mean()
    assert inside.mean() > 0.97


# ------------------------------------------------------------------- determinism and limits


def test_same_seed_same_arrays_different_seed_differs():
    p = load_params(SPECIES[0].parent / "quaking_aspen.txt")
    a, b, c = generate(p, 7), generate(p, 7), generate(p, 8)
    for f in dataclasses.fields(a):
        va, vb = getattr(a, f.name), getattr(b, f.name)
        if isinstance(va, np.ndarray):
            assert np.array_equal(va, vb), f.name
    assert not np.array_equal(a.node_pos[:50], c.node_pos[:50])


def test_size_estimate_refuses_with_the_flag_named():
    p = load_params(SPECIES[0].parent / "weeping_willow.txt")
    with pytest.raises(TreegenError, match="--max-leaves"):
        generate(p, 0, GenerateOptions(max_leaves=10_000))
    with pytest.raises(TreegenError, match="--max-stems"):
        generate(p, 0, GenerateOptions(max_stems=1_000))
    stems, leaves = estimate_counts(p)
    assert stems > 1_000 and leaves > 10_000


def test_global_rng_untouched():
    np.random.seed(123)
    before = np.random.random()
    np.random.seed(123)
    generate(_params(levels=3, leaves=5.0), seed=1)
    assert np.random.random() == before


# ------------------------------------------------------------------- every species


@pytest.fixture(scope="module", params=[s.stem for s in SPECIES])
def species_tree(request):
    p = load_params(SPECIES[0].parent / f"{request.param}.txt")
    return p, generate(p, seed=0)


def test_species_generates_and_matches_its_estimate(species_tree):
    p, t = species_tree
    assert t.n_stems >= 1 and t.n_nodes >= 2 * t.n_stems
    stems, leaves = estimate_counts(p)
    assert 0.3 * stems <= t.n_stems <= 3 * stems + 10
    if leaves:
        assert 0.3 * leaves <= t.n_leaves <= 3 * leaves + 10
    for name in ("node_pos", "node_frame", "node_radius", "leaf_pos", "leaf_frame", "leaf_size"):
        assert np.all(np.isfinite(getattr(t, name))), name


def test_children_start_on_their_parent(species_tree):
    _, t = species_tree
    kids = np.flatnonzero((t.stem_parent >= 0) & ~t.stem_clone)
    base = t.node_pos[t.stem_node_start[kids]]
    a = t.node_pos[t.stem_parent_node[kids]]
    b = t.node_pos[t.stem_parent_node[kids] + 1]
    ab = b - a
    s = np.clip(np.einsum("ij,ij->i", base - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18), 0, 1)
    gap = np.linalg.norm(a + ab * s[:, None] - base, axis=1)
    assert np.all(gap <= 1e-6 * np.maximum(1.0, t.scale))
    assert np.all(t.node_stem[t.stem_parent_node[kids]] == t.stem_parent[kids])


def test_radii_positive_and_non_increasing(species_tree):
    p, t = species_tree
    assert np.all(t.node_radius > 0) and np.all(t.stem_radius > 0)
    same_stem = t.node_stem[1:] == t.node_stem[:-1]
    taper_ok = np.array([p.level[min(lv, 9)].taper <= 2.0 for lv in t.stem_level[t.node_stem[1:]]])
    d = np.diff(t.node_radius)[same_stem & taper_ok]
    assert np.all(d <= 1e-12)


def test_frames_are_rotations(species_tree):
    _, t = species_tree
    for frames in (t.node_frame, t.leaf_frame):
        if len(frames):
            eye = np.einsum("nji,njk->nik", frames, frames)
            assert np.allclose(eye, np.eye(3), atol=1e-9)
            assert np.allclose(np.linalg.det(frames), 1.0, atol=1e-9)


def test_leaves_attach_to_nodes_of_their_stem(species_tree):
    p, t = species_tree
    if not t.n_leaves:
        return
    assert np.all(t.node_stem[t.leaf_node] == t.leaf_stem)
    # the blade base sits within one segment plus the petiole of its node
    seg = np.linalg.norm(t.node_pos[t.leaf_node + 1] - t.node_pos[t.leaf_node], axis=1)
    reach = np.linalg.norm(t.leaf_pos - t.node_pos[t.leaf_node], axis=1)
    assert np.all(reach <= seg + abs(p.leaf_stem_len) * t.leaf_size[:, 0] + 1e-9)


@pytest.mark.parametrize("name", ["quaking_aspen", "weeping_willow", "european_larch", "palm"])
def test_regrow_leaves_equals_a_full_regrow(name):
    """Geometric LODs take the stems from LOD0 and regrow only leaves: it must be exactly what
    generate() would grow with the same overrides."""
    from treegen_cli.generate import regrow_leaves

    p = load_params(SPECIES[0].parent / f"{name}.txt")
    tree = generate(p, 4)
    for levels, quality, leaves in [(None, 0.5, p.leaves), (p.levels - 1, 0.25, p.leaves * 3)]:
        q = dataclasses.replace(p, leaves=leaves)
        opts = GenerateOptions(levels=levels, leaf_quality=quality)
        a, b = generate(q, 4, opts), regrow_leaves(tree, q, opts)
        assert a.params == b.params
        for f in dataclasses.fields(a):
            if isinstance(getattr(a, f.name), np.ndarray):
                assert np.array_equal(getattr(a, f.name), getattr(b, f.name)), f.name


def test_branch_dist_zero_makes_whorls():
    """nBranchDist 0 gathers each parent segment's children at the segment base (conifers);
    1 keeps the paper's even spread."""
    p = _level(_params(levels=2), 1, branches=24)
    p = _level(p, 0, curve_res=6)
    even = generate(_level(p, 1, branch_dist=1.0), seed=0)
    whorl = generate(_level(p, 1, branch_dist=0.0), seed=0)
    seg_len = whorl.stem_length[0] / 6
    offsets = whorl.stem_offset[whorl.stem_level == 1]
    assert len(np.unique(np.round(offsets, 9))) <= 6
    on_boundary = np.isclose(offsets / seg_len, np.round(offsets / seg_len)) | np.isclose(
        offsets, whorl.stem_length[0] * whorl.params.base_size
    )
    assert np.all(on_boundary)
    assert len(np.unique(np.round(even.stem_offset[even.stem_level == 1], 9))) == 24


def test_split_correction_brings_split_limbs_back_to_their_declination():
    """After a split each member tilts by the split angle and its remaining segments turn back
    by the same amount in total, however many splits it went through."""
    p = _level(
        _params(levels=1, attraction_up=0.0),
        0,
        curve_res=12,
        curve=0.0,
        curve_v=0.0,
        seg_splits=0.3,
        split_angle=30.0,
        split_angle_v=0.0,
    )
    t = generate(p, seed=0)
    assert t.stem_clone.sum() >= 3
    tips = t.stem_node_start + t.stem_node_count - 1
    lean = np.degrees(np.arccos(np.clip(t.node_frame[tips, :, 2][:, 2], -1, 1)))
    # the last split a member went through: its own start or a clone split off it later
    seg_of = np.rint(t.node_z[t.stem_node_start] / (t.stem_length / 12)).astype(int)
    last_split = seg_of.copy()
    np.maximum.at(last_split, t.stem_parent[t.stem_clone], seg_of[t.stem_clone])
    # a split at the last inner node (11) has no segment left to correct on
    early = last_split <= 10
    assert early.sum() >= 3
    assert np.all(lean[early] < 1e-4)  # degrees
    assert np.any(lean[~early] > 10.0)  # the uncorrected ones still lean


def test_helix_members_keep_their_own_helix_after_a_split():
    p = _level(
        _params(levels=1), 0, curve_res=6, curve_v=-30.0, seg_splits=0.5, split_angle=40.0, split_angle_v=0.0
    )
    t = generate(p, seed=0)
    clones = np.flatnonzero(t.stem_clone)
    assert clones.size
    for c in clones:
        mine = t.node_frame[t.stem_node_start[c] : t.stem_node_start[c] + t.stem_node_count[c], :, 2]
        parent = t.stem_parent[c]
        first = (
            t.stem_node_start[parent]
            + (t.stem_node_start[c] - t.stem_node_start[c])
            + int(round(t.node_z[t.stem_node_start[c]] / (t.stem_length[0] / 6)))
            - int(round(t.node_z[t.stem_node_start[parent]] / (t.stem_length[0] / 6)))
        )
        theirs = t.node_frame[first : first + len(mine), :, 2]
        # after the split node the member and its origin point in different directions
        assert np.all(np.einsum("ij,ij->i", mine[1:-1], theirs[1 : len(mine) - 1]) < 0.9999)


def test_prune_ratio_blends_pruned_and_free_length():
    """Final length L0 − (L0 − L_fit)·PruneRatio: half pruning lands between none and full."""
    p = _params(levels=2, prune_width=0.25, prune_width_peak=0.5)
    free, half, full = (generate(dataclasses.replace(p, prune_ratio=r), seed=0) for r in (0, 0.5, 1))
    L0, Lh, Lf = (t.stem_length[t.stem_level == 1] for t in (free, half, full))
    assert len(L0) == len(Lh) == len(Lf)  # nothing pruned away entirely here
    assert np.all(Lf <= L0 + 1e-12) and np.any(Lf < 0.9 * L0)
    assert np.allclose(Lh, L0 - (L0 - Lf) * 0.5, rtol=1e-9)


def test_curve_turns_the_stem_by_ncurve():
    """nCurve turns a stem by nCurve/nCurveRes per segment after the first (Arbaro's count)."""
    p = _level(_params(levels=1), 0, curve_res=5, curve=60.0, curve_v=0.0)
    t = generate(p, seed=0)
    d = t.node_frame[: t.stem_node_count[0] - 1, :, 2]
    turn = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", d[1:], d[:-1]), -1, 1)))
    assert np.allclose(turn, 12.0, atol=1e-6)
