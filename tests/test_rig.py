"""Skeleton under a joint budget: hierarchy, rest transforms, bindings (synthetic + species)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from synthetic_tree import species_tree, synthetic_tree
from treegen_cli.errors import TreegenError
from treegen_cli.rig import RigOptions, build_rig


def compose(skel, rotation=None, translation=None) -> np.ndarray:
    """World matrices from the local rest transforms (optionally overridden), parent first."""
    q = skel.rest_rotation if rotation is None else rotation
    t = skel.rest_translation if translation is None else translation
    J = len(skel.names)
    local = np.zeros((J, 4, 4))
    local[:, :3, :3] = Rotation.from_quat(q).as_matrix()
    local[:, :3, 3] = t
    local[:, 3, 3] = 1.0
    world = np.empty_like(local)
    for j in range(J):  # a few hundred joints in a test
        world[j] = local[j] if skel.parent[j] < 0 else world[skel.parent[j]] @ local[j]
    return world


def full_joint_count(tree) -> int:
    """Every segment-start node is a joint, except a clone's first (it is the split node)."""
    return int(np.sum(tree.stem_node_count - 1) - np.count_nonzero(tree.stem_clone))


def check_rig(tree, rig, budget):
    skel = rig.skeleton
    J = len(skel.names)
    assert 1 <= J <= budget
    assert len(set(skel.names)) == J
    # A tree rooted at the trunk base, parents listed before children.
    assert skel.parent[0] == -1 and rig.joint_node[0] == tree.stem_node_start[0]
    assert np.all(skel.parent[1:] >= 0) and np.all(skel.parent[1:] < np.arange(1, J))
    # Joints sit on their nodes, and the local rest transforms compose to bind_world.
    np.testing.assert_allclose(skel.bind_world[:, :3, 3], tree.node_pos[rig.joint_node], atol=1e-9)
    np.testing.assert_allclose(compose(skel), skel.bind_world, atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(skel.bind_world[:, :3, :3]), 1.0, atol=1e-9)
    # Bindings: valid joints, weights in [0, 1] summing to 1, unused slot (0, 0).
    assert rig.node_joints.dtype == np.uint16 and rig.node_weights.dtype == np.float32
    assert rig.node_joints.max() < J and rig.leaf_joint.max(initial=0) < J
    w = rig.node_weights
    assert np.all((w >= 0) & (w <= 1))
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-6)
    assert np.all(rig.node_joints[w[:, 1] == 0, 1] == 0)
    # A jointed node is bound to its own joint alone.
    assert np.all(rig.node_joints[rig.joint_node, 0] == np.arange(J))
    np.testing.assert_allclose(w[rig.joint_node, 0], 1.0)
    # Each joint's parent sits on the same stem below it, or on an ancestor stem.
    pn = rig.joint_node[skel.parent[1:]]
    js = rig.joint_stem[1:]
    same = rig.joint_stem[skel.parent[1:]] == js
    assert np.all(pn[same] < rig.joint_node[1:][same])
    assert np.all(np.isin(rig.joint_stem[skel.parent[1:]][~same], np.concatenate([tree.stem_parent, [0]])))


def test_full_budget_puts_a_joint_on_every_segment_start():
    tree = synthetic_tree()
    rig = build_rig(tree)
    check_rig(tree, rig, 256)
    assert len(rig.joint_node) == full_joint_count(tree) == 14
    # No tip node is a joint; every other node is (clone's base aliases the split node).
    tips = tree.stem_node_start + tree.stem_node_count - 1
    assert not np.isin(tips, rig.joint_node).any()
    # The clone's first joint hangs from the joint on the trunk's split node (trunk node 2).
    clone_first = np.flatnonzero(rig.joint_stem == 1)[0]
    assert rig.joint_node[rig.skeleton.parent[clone_first]] == tree.stem_parent_node[1] == 2
    # The clone's base node is bound to the split joint; children attach to their carrier.
    assert rig.node_joints[tree.stem_node_start[1], 0] == 2
    assert rig.joint_node[rig.stem_joint[2]] == tree.stem_parent_node[2]


@pytest.mark.parametrize("budget", [1, 2, 3, 5, 8, 12, 13, 14, 256])
def test_budget_never_exceeded_and_rig_valid(budget):
    tree = synthetic_tree()
    rig = build_rig(tree, RigOptions(max_joints=budget))
    check_rig(tree, rig, budget)


def test_budget_drops_finest_levels_first_then_coarsens():
    tree = synthetic_tree()
    lev = lambda rig: tree.stem_level[rig.joint_stem]  # noqa: E731
    r12 = build_rig(tree, RigOptions(max_joints=12))
    # Level 2 (3 joints in full) does not fit: only its longest stem keeps a base joint.
    assert len(r12.joint_node) == 12
    assert set(r12.joint_stem[lev(r12) == 2]) == {4}
    r8 = build_rig(tree, RigOptions(max_joints=8))
    assert not np.any(lev(r8) == 2)
    # Level 1 coarsened, yet each level-1 stem keeps its base node.
    assert np.isin(tree.stem_node_start[[2, 3]], r8.joint_node).all()
    assert np.count_nonzero(lev(r8) == 1) < 6
    r5 = build_rig(tree, RigOptions(max_joints=5))
    assert np.all(lev(r5) == 0) and len(r5.joint_node) == 5
    r1 = build_rig(tree, RigOptions(max_joints=1))
    assert list(r1.joint_node) == [0]
    assert np.all(r1.node_joints == 0) and np.all(r1.node_weights[:, 0] == 1)


def test_coarse_chain_blends_by_node_z():
    tree = synthetic_tree()
    rig = build_rig(tree, RigOptions(max_joints=2))  # trunk joints on nodes 0 and 2
    assert list(rig.joint_node) == [0, 2]
    # Trunk node 1 (z = 2) lies halfway between joints at z = 0 and z = 4.
    assert list(rig.node_joints[1]) == [0, 1]
    np.testing.assert_allclose(rig.node_weights[1], [0.5, 0.5])
    # Beyond the last joint of a chain: rigid to it.
    assert list(rig.node_joints[3]) == [1, 0] and list(rig.node_weights[3]) == [1, 0]
    # Leaves collapse to their node's dominant joint.
    dom = rig.node_joints[tree.leaf_node, np.argmax(rig.node_weights[tree.leaf_node], axis=1)]
    np.testing.assert_array_equal(rig.leaf_joint, dom)


def test_jointless_stem_moves_with_the_drawn_bark_of_a_coarse_chain(monkeypatch):
    """Trunk joints on nodes 0 and 2 only: stem 2 (no joints) grows from trunk segment 1 (nodes
    1-2, node 1 blended half-way) at t = 0.5. The drawn bark there is straight between the two
    rings' skinned centres; under any pose the stem's base, skinned with its own binding, is
    exactly that point (a blend of the ends' weights would put 0.75 on joint 1, not 0.5)."""
    tree = synthetic_tree()
    chosen = np.zeros(tree.n_nodes, dtype=bool)
    chosen[[0, 2]] = True
    monkeypatch.setattr("treegen_cli.rig._select", lambda tree, options, among: chosen)
    rig = build_rig(tree)
    base = tree.stem_node_start[2]
    np.testing.assert_allclose(rig.node_weights[base], [0.5, 0.5], atol=1e-6)
    rng = np.random.default_rng(3)
    for _ in range(5):
        turn = Rotation.from_rotvec(rng.normal(0.0, 0.6, (2, 3))).as_matrix()
        skin = np.tile(np.eye(4), (2, 1, 1))
        for j in range(2):  # joint j turns about its pivot, children follow
            p = tree.node_pos[rig.joint_node[j]]
            m = np.eye(4)
            m[:3, :3], m[:3, 3] = turn[j], p - turn[j] @ p
            skin[j] = (skin[rig.skeleton.parent[j]] if j else np.eye(4)) @ m

        def skinned(node: int, point: np.ndarray) -> np.ndarray:
            w, jj = rig.node_weights[node].astype(float), rig.node_joints[node].astype(int)
            return sum(w[k] * (skin[jj[k]] @ np.r_[point, 1.0])[:3] for k in range(2))

        a, b = 1, 2
        bark = 0.5 * skinned(a, tree.node_pos[a]) + 0.5 * skinned(b, tree.node_pos[b])
        np.testing.assert_allclose(skinned(base, tree.node_pos[base]), bark, atol=1e-9)


def test_joint_levels_restrict_and_rigid_stems_ride_on_their_carrier():
    tree = synthetic_tree()
    rig = build_rig(tree, RigOptions(joint_levels=(0,)))
    check_rig(tree, rig, 256)
    assert np.all(tree.stem_level[rig.joint_stem] == 0)
    # Stem 2 grows from trunk segment 1 at z = 3, half-way between the trunk joints on nodes 1
    # and 2. The trunk's bark there is drawn straight between its rings on nodes 1 and 2, whose
    # centres move with joint 1 (node 2 is joint 2's pivot): so all its nodes and its child's
    # take joint 1 alone, and ride exactly as that bark; leaves ride on it too.
    j = np.flatnonzero(rig.joint_node == 1)[0]
    nodes2 = np.flatnonzero(np.isin(tree.node_stem, [2, 4]))
    assert np.all(rig.node_joints[nodes2, 0] == j)
    np.testing.assert_allclose(rig.node_weights[nodes2], [[1.0, 0.0]] * len(nodes2))
    assert np.all(rig.leaf_joint[tree.leaf_stem == 4] == j)
    # Levels that skip the trunk still get the trunk base as root.
    r2 = build_rig(tree, RigOptions(joint_levels=(2,)))
    check_rig(tree, r2, 256)
    assert r2.joint_node[0] == 0 and set(tree.stem_level[r2.joint_stem[1:]]) == {2}


@pytest.mark.parametrize("budget", [0, -3])
def test_budget_below_one_is_a_user_error(budget):
    with pytest.raises(TreegenError, match="max-joints"):
        build_rig(synthetic_tree(), RigOptions(max_joints=budget))


@pytest.mark.parametrize("species", ["quaking_aspen", "lombardy_poplar", "black_tupelo"])
def test_species_rig_under_several_budgets(species):
    tree = species_tree(species, seed=1)
    for budget in (1, 2, 5, 64, 256):
        rig = build_rig(tree, RigOptions(max_joints=budget))
        check_rig(tree, rig, budget)
        if full_joint_count(tree) > budget:
            assert len(rig.joint_node) > budget // 2  # the budget is used, not wasted


BUDGETS = (16, 40, 64, 100, 150, 200, 256)


@pytest.mark.parametrize("species", ["quaking_aspen", "black_tupelo", "ca_black_oak", "fan_palm"])
def test_species_rig_uses_the_whole_budget(species):
    """The rig has min(budget, candidate nodes) joints: the budget is spent, not rounded down to
    a chain stride (the aspen got 53 joints for 64 and for 100). The fan palm has 249 candidates."""
    tree = species_tree(species, seed=0)
    for budget in BUDGETS:
        rig = build_rig(tree, RigOptions(max_joints=budget))
        check_rig(tree, rig, budget)
        assert len(rig.joint_node) == min(budget, full_joint_count(tree))
    # Restricted to level 1: the pool is the root and level 1's candidates.
    one = tree.stem_level == 1
    pool = 1 + int(np.sum(tree.stem_node_count[one] - 1) - np.count_nonzero(tree.stem_clone[one]))
    for budget in (2, 40, 100):
        rig = build_rig(tree, RigOptions(max_joints=budget, joint_levels=(1,)))
        check_rig(tree, rig, budget)
        assert len(rig.joint_node) == min(budget, pool)


def _pieces(tree, rig) -> np.ndarray:
    """Per stem: its longest jointless piece (m along node_z) from a joint of its own to the next
    or to the tip; NaN for a stem without joints of its own."""
    own = np.bincount(rig.joint_stem, minlength=tree.n_stems)
    tip = tree.stem_node_start + tree.stem_node_count - 1
    ends = np.concatenate([rig.joint_node, tip[own > 0]])
    stem = tree.node_stem[ends]
    order = np.lexsort((ends, stem))
    ends, stem = ends[order], stem[order]
    gap = np.where(stem[1:] == stem[:-1], np.diff(tree.node_z[ends]), -np.inf)
    out = np.full(tree.n_stems, -np.inf)
    np.maximum.at(out, stem[:-1], gap)
    return np.where(own > 0, out, np.nan)


@pytest.mark.parametrize("species", ["quaking_aspen", "black_tupelo", "weeping_willow", "ca_black_oak"])
def test_joints_spread_as_the_budget_grows(species):
    """More budget never takes a joint from a stem; levels fill from the trunk down; the level
    being filled has a joint at every stem's base (once they fit) and its longest jointless
    piece shrinks as the budget grows; no chain of it is left coarser than the pieces another
    was split into (the old stride rule split short and long chains alike)."""
    tree = species_tree(species, seed=0)
    level = tree.stem_level
    full = np.bincount(tree.node_stem, minlength=tree.n_stems) - 1 - tree.stem_clone
    prev_count, prev_piece = np.zeros(tree.n_stems, dtype=np.int64), {}
    for budget in BUDGETS:
        rig = build_rig(tree, RigOptions(max_joints=budget))
        count = np.bincount(rig.joint_stem, minlength=tree.n_stems)
        assert np.all(count >= prev_count)
        prev_count = count
        filled = np.array([np.all(count[level == lv] == full[level == lv]) for lv in range(level.max() + 1)])
        partial = int(np.argmin(filled)) if not filled.all() else None
        if partial is None:
            continue
        assert not np.any(count[level > partial])  # deeper levels wait for this one
        on = (level == partial) & ~tree.stem_clone
        if budget - count[level < partial].sum() >= np.count_nonzero(on):
            assert np.all(count[on] >= 1)  # every stem's base first
            # Balance: with m extra joints a chain's pieces average length / (m + 1); no chain
            # of the level (clones too) is left coarser than the pieces another was split into.
            lv = np.flatnonzero(level == partial)
            tip = tree.stem_node_start[lv] + tree.stem_node_count[lv] - 1
            length = tree.node_z[tip] - tree.node_z[tree.stem_node_start[lv]]
            m = count[lv] - ~tree.stem_clone[lv]
            room = m < tree.stem_node_count[lv] - 2
            if room.any() and (m > 0).any():
                assert (length[room] / (m[room] + 1)).max() <= (length[m > 0] / m[m > 0]).min() + 1e-9
            piece = np.nanmax(_pieces(tree, rig)[on])
            assert piece <= prev_piece.get(partial, np.inf) + 1e-9
            prev_piece[partial] = piece


@pytest.mark.parametrize("species", ["quaking_aspen", "ca_black_oak"])
def test_among_restricts_the_joints_and_keeps_the_budget_rules(species):
    """`among` (a LOD's: LOD0's joint nodes) only takes joints away from the pool: all nodes
    allowed, the rig is the unrestricted one; some, the joints are among them, and the budget
    is spent while they last, a level coarsening as it would (every kept stem's base first)."""
    tree = species_tree(species, seed=0)
    base = build_rig(tree, RigOptions(max_joints=256))
    every = build_rig(tree, RigOptions(max_joints=256), among=np.arange(tree.n_nodes))
    assert np.array_equal(every.joint_node, base.joint_node)
    assert every.skeleton.names == base.skeleton.names
    for budget in (1, 16, 64, 128, 256, 400):
        rig = build_rig(tree, RigOptions(max_joints=budget), among=base.joint_node)
        check_rig(tree, rig, budget)
        assert np.isin(rig.joint_node, base.joint_node).all()
        assert len(rig.joint_node) == min(budget, len(base.joint_node))
        based = np.isin(tree.stem_node_start[rig.joint_stem], rig.joint_node)
        assert based[~tree.stem_clone[rig.joint_stem]].all()  # no own stem's joints without its base
