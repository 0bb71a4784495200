"""Tree → skeleton whose joints are stem nodes, under a joint budget.

Result: every stem node that starts a segment may become a joint (a joint at a stem's tip would
rotate nothing), chained along its stem and hung from the parent stem's joint at the attach
point; stems without joints ride rigidly on the nearest ancestor joint.

    rig = build_rig(tree, RigOptions(max_joints=128))   # → len(rig.skeleton.names) <= 128,
    rig.skeleton.parent[0] == -1                         #   joint 0 on the trunk base node

Budget (never exceeded, and used: the rig has min(budget, candidate nodes) joints): levels are
filled from the trunk down. A level whose full chains fit gets them; the first level that does
not fit gets a joint at every stem's base and spends the rest of the budget along its chains,
a stem's share growing with its length (the longest jointless spans are split first, D'Hondt
style), spaced evenly from base to tip; deeper levels get no joints. If even one joint per stem
does not fit, only that level's longest stems get one (at their base).

A LOD cut from LOD0's tree is rigged `among` LOD0's joints (build_rig): the same rules over the
LOD0 joints it keeps, in their frames, so its skeleton is LOD0's with joints removed, named
and posed as there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .asset import Skeleton
from .errors import TreegenError


@dataclass(frozen=True, eq=False)
class Rig:
    skeleton: Skeleton
    joint_node: np.ndarray  # int32 (J,): the tree node each joint sits on
    joint_stem: np.ndarray  # int32 (J,): the stem that node belongs to
    node_joints: np.ndarray  # uint16 (N, 2): skin binding of a point at each node: the jointed
    node_weights: np.ndarray  # float32 (N, 2)  nodes enclosing it on its chain, weights sum 1
    # (rigidly carried nodes: (carrier, 0) with weights (1, 0))
    leaf_joint: np.ndarray  # uint16 (L,): joint carrying each leaf rigidly
    stem_joint: np.ndarray  # int32 (S,): joint carrying the stem's base (its attach joint)


@dataclass(frozen=True)
class RigOptions:
    """max_joints: hard budget (≥ 1). joint_levels: stem levels allowed to own joints
    (None = all); the trunk base is always the root joint."""

    max_joints: int = 256
    joint_levels: tuple[int, ...] | None = None


RIG_DEFAULTS = RigOptions()

MAX_JOINTS = 65535  # skin joint indices are uint16


def _chain_shares(length: np.ndarray, free: np.ndarray, extra: int) -> np.ndarray:
    """Extra joints per chain (int64, like `free`): `extra` joints in all, at most `free[i]` on
    chain i, each to the chain whose pieces are then longest (D'Hondt: chain i's j-th extra joint
    bids length[i] / j, the highest `extra` bids win; ties go to the earlier chain). Splitting
    the longest jointless span first is where a joint adds the most bending."""
    chain_of = np.repeat(np.arange(len(free)), free)
    j = np.arange(len(chain_of)) - np.repeat(np.cumsum(free) - free, free) + 1
    won = np.lexsort((j, chain_of, -length[chain_of] / j))[:extra]
    return np.bincount(chain_of[won], minlength=len(free))


def _select(tree, options: RigOptions, among: np.ndarray | None = None) -> np.ndarray:
    """Bool (N,): which nodes become joints, following the budget rules in the module doc;
    only nodes whose LOD0 node (Tree.lod0_nodes) is in `among` if given (see build_rig)."""
    level = tree.stem_level.astype(np.int64)
    clone = tree.stem_clone.astype(bool)
    chain = tree.stem_node_count.astype(np.int64) - 1  # segment-start nodes per stem (tip: chain)
    start = tree.stem_node_start.astype(np.int64)
    s = tree.node_stem
    p = np.arange(tree.n_nodes) - start[s]  # position along the stem
    candidate = (p < chain[s]) & ~(clone[s] & (p == 0))  # a clone's 0 is its parent's split node
    if among is not None:
        candidate &= np.isin(tree.lod0_nodes, among)
    # A stem's slots: its base (a clone's is its parent's split node, never a joint) and its
    # other candidates in order; with every node allowed, slot q is the node at position q.
    based = ~clone & candidate[start]
    later = np.flatnonzero(candidate & (p > 0))
    n_later = np.bincount(s[later], minlength=tree.n_stems)
    first_later = np.cumsum(n_later) - n_later
    jointed = np.zeros(tree.n_nodes, dtype=bool)
    budget = options.max_joints
    roots = np.flatnonzero((tree.stem_parent < 0) & based)

    present = np.unique(level)
    allowed = (
        present
        if options.joint_levels is None
        else np.intersect1d(present, np.asarray(options.joint_levels, dtype=np.int64))
    )
    if 0 not in allowed:  # the root joint exists regardless
        jointed[start[roots[:budget]]] = True
        budget -= int(min(len(roots), budget))
    for lev in allowed:
        idx = np.flatnonzero(level == lev)
        own = idx[based[idx]]
        full = len(own) + int(n_later[idx].sum())
        if full <= budget:  # every candidate of the level
            jointed |= candidate & (level[s] == lev)
            budget -= full
            continue
        if len(own) <= budget:
            # Every stem's base, then the rest spread along the chains (fewer than their free
            # slots 1..n-1, since the full chains did not fit): m extra joints on a chain of
            # n slots at slots round(i * n / (m + 1)), i = 1..m — distinct, as m < n.
            jointed[start[own]] = True
            free = n_later[idx]
            length = tree.node_z[start[idx] + chain[idx]] - tree.node_z[start[idx]]
            m = _chain_shares(length, free, budget - len(own))
            rep = np.repeat(np.arange(len(idx)), m)
            i = np.arange(len(rep)) - np.repeat(np.cumsum(m) - m, m) + 1
            n, mm = free[rep] + 1, m[rep]
            slot = (2 * i * n + mm + 1) // (2 * (mm + 1))
            jointed[later[first_later[idx][rep] + slot - 1]] = True
        else:
            # Not even one joint per stem: the longest (non-clone) stems keep a base joint.
            is_root = tree.stem_parent[own] < 0
            order = np.lexsort((-tree.stem_length[own], ~is_root))
            jointed[start[own[order[:budget]]]] = True
        break  # this level was coarsened: deeper levels get none
    return jointed


def joint_names(tree, joint_node: np.ndarray, joint_stem: np.ndarray) -> list[str]:
    """Names that say what a joint is and stay the same for every instance of a tree and in
    every LOD: "trunk_K" (or "trunkS_K" with several trunks) and "bS_K" for branch stem S, K
    the node along the stem, both numbered as in LOD0's tree (Tree.lod0_stems, lod0_nodes: a
    LOD drops stems and nodes), so a name is one place in every LOD, as engines matching a
    LOD's bones to LOD0's by name need.

    Result: a single trunk with joints on nodes 0 and 3 and one on branch 12's node 2 →
    ["trunk_0", "trunk_3", "b12_2"]."""
    nodes0 = tree.lod0_nodes
    k = nodes0[joint_node] - nodes0[tree.stem_node_start[joint_stem]]  # a stem keeps its base
    level = tree.stem_level[joint_stem]
    single = np.count_nonzero(tree.stem_level == 0) <= 1  # a LOD keeps every trunk
    return [
        (f"trunk_{kk}" if single else f"trunk{ss}_{kk}") if lv == 0 else f"b{ss}_{kk}"
        for ss, kk, lv in zip(tree.lod0_stems[joint_stem].tolist(), k.tolist(), level.tolist())
    ]  # ≤ 256


def check_joint_levels(levels: int, options: RigOptions, flag: str = "--joint-levels") -> None:
    """Before growing: `joint_levels` must name at least one stem level the species has
    (0..Levels-1), else the skeleton is the root joint alone and nothing sways. Levels it lacks
    are ignored otherwise, so one list can serve species of different depths (a catalogue)."""
    given = options.joint_levels
    if given is None or any(0 <= n < levels for n in given):
        return
    raise TreegenError(
        f"{flag} '{','.join(map(str, given))}': the species has stem levels 0..{levels - 1} "
        f"(Levels {levels}); name at least one, else only the root joint is left and nothing sways"
    )


def build_rig(
    tree,
    options: RigOptions = RIG_DEFAULTS,
    among: np.ndarray | None = None,
    frames: np.ndarray | None = None,
) -> Rig:
    """Joints on stem nodes under `options.max_joints`, with node and leaf skin bindings.
    `among`: LOD0's joint nodes (its rig's joint_node), for a LOD cut from LOD0's tree: the
    LOD joints only nodes of those it keeps, so its skeleton is LOD0's with joints removed
    (same names, each joint's parent its nearest ancestor in LOD0 the LOD keeps), as an
    engine importing the LODs of one skeletal mesh needs (Unreal: a LOD's bones are a subset
    of LOD0's, matched by name). `frames` (len(among), 3, 3): LOD0's joint frames there, taken
    as the LOD's (its coarsened tree turns a kept node's frame along the new segment, up to
    13° at LOD3): same bind pose, so LOD0's animation can drive a LOD's bones."""
    if not 1 <= options.max_joints <= MAX_JOINTS:
        raise TreegenError(f"--max-joints {options.max_joints}: the joint budget must be in 1..{MAX_JOINTS}")
    N = tree.n_nodes
    nid = np.arange(N)
    s = tree.node_stem
    jointed = _select(tree, options, among)
    joint_node = np.flatnonzero(jointed).astype(np.int32)
    J = len(joint_node)
    joint_of = np.cumsum(jointed) - 1  # joint index at jointed nodes

    # Carrier: the last joint at or below the node on its own chain, else the attach joint.
    last_own = np.maximum.accumulate(np.where(jointed, nid, -1))
    has_prev = (last_own >= 0) & (s[np.maximum(last_own, 0)] == s)
    carrier = np.where(has_prev, joint_of[np.maximum(last_own, 0)], -1)
    attach = tree.stem_parent_node[s]
    carrier[(carrier < 0) & (attach < 0)] = 0  # extra trunks hang from the root
    while (todo := carrier < 0).any():  # one pass per stem generation
        carrier[todo] = carrier[attach[todo]]

    # Blend toward the next joint of the own chain, linearly in node_z.
    nxt = np.minimum.accumulate(np.where(jointed, nid, N)[::-1])[::-1]
    nxt = np.append(nxt[1:], N)  # strictly after the node
    has_next = (nxt < N) & (s[np.minimum(nxt, N - 1)] == s)
    z = tree.node_z
    z_prev = np.where(has_prev, z[np.maximum(last_own, 0)], z[tree.stem_node_start[s]])
    z_next = z[np.minimum(nxt, N - 1)]
    span = np.where(has_next, z_next - z_prev, 1.0)
    w = np.where(has_next, np.clip((z - z_prev) / np.where(span > 0, span, 1.0), 0.0, 1.0), 0.0)
    node_joints = np.zeros((N, 2), dtype=np.uint16)
    node_joints[:, 0] = carrier
    node_joints[:, 1] = np.where(w > 0, joint_of[np.minimum(nxt, N - 1)], 0)
    node_weights = np.column_stack([1.0 - w, w]).astype(np.float32)
    # A stem without joints of its own takes its parent's skin binding where it attaches (the
    # binding that moves that point as the parent's drawn bark does, below), so it can never
    # separate from it; riding rigidly on one joint let it float off wherever the parent blends
    # two. Both end bindings only ever use the segment's two chain joints. One pass per stem
    # generation.
    rigid = np.flatnonzero(~has_prev & (attach >= 0))
    stem_of = s[rigid]
    a = attach[rigid]
    b = np.where((a + 1 < N) & (s[np.minimum(a + 1, N - 1)] == s[a]), a + 1, a)
    ab = tree.node_pos[b] - tree.node_pos[a]
    base = tree.node_pos[tree.stem_node_start[stem_of]]
    t = np.clip(
        np.einsum("ij,ij->i", base - tree.node_pos[a], ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-24),
        0.0,
        1.0,
    )
    todo = rigid
    while todo.size:
        k = np.searchsorted(rigid, todo)
        ja, wa = node_joints[a[k]].astype(np.int64), node_weights[a[k]].astype(np.float64)
        jb, wb = node_joints[b[k]].astype(np.int64), node_weights[b[k]].astype(np.float64)
        cand = np.concatenate([ja, jb], axis=1)
        wt = np.concatenate([wa * (1.0 - t[k, None]), wb * t[k, None]], axis=1)
        first = cand[:, 0]
        w0 = np.sum(np.where(cand == first[:, None], wt, 0.0), axis=1)
        other = np.where((cand != first[:, None]) & (wt > 0.0), wt, -1.0)
        second = cand[np.arange(len(todo)), np.argmax(other, axis=1)]
        has2 = other.max(axis=1) > 0.0
        # The bark between the two rings is drawn straight between their skinned centres, so
        # the axis point there moves by (1 − t)·Δ_a + t·Δ_b; blending the weights instead would
        # sag it by t(1 − t)·(M_a − M_b)(c_b − c_a) (centimetres at 12 m/s). The two joints are
        # consecutive on one chain, the later (its pivot p) turning about the earlier; the
        # weight β on it that puts the point where the bark is solves
        # β (x − p) = (1 − t) α_a (c_a − p) + t α_b (c_b − p)   (α: each end's weight on it),
        # exact when p is on the segment's line (least squares otherwise).
        desc = np.maximum(first, second)
        alpha_a = np.sum(np.where(ja == desc[:, None], wa, 0.0), axis=1)
        alpha_b = np.sum(np.where(jb == desc[:, None], wb, 0.0), axis=1)
        pivot = tree.node_pos[joint_node[desc]]
        ca, cb, tk = tree.node_pos[a[k]] - pivot, tree.node_pos[b[k]] - pivot, t[k, None]
        x = ca + tk * (cb - ca)
        rhs = (1.0 - tk) * alpha_a[:, None] * ca + tk * alpha_b[:, None] * cb
        den = np.einsum("ij,ij->i", x, x)
        beta = np.where(
            den > 1e-18,
            np.einsum("ij,ij->i", rhs, x) / np.maximum(den, 1e-18),
            (1.0 - t[k]) * alpha_a + t[k] * alpha_b,
        )
        beta = np.clip(beta, 0.0, 1.0)
        w0 = np.where(first == desc, beta, 1.0 - beta)
        node_joints[todo, 0] = first
        node_joints[todo, 1] = np.where(has2, second, 0)
        node_weights[todo, 0] = np.where(has2, w0, 1.0)
        node_weights[todo, 1] = np.where(has2, 1.0 - w0, 0.0)
        node_joints[todo, 1] = np.where(node_weights[todo, 1] > 0, node_joints[todo, 1], 0)
        todo = todo[np.isin(a[k], todo) | np.isin(b[k], todo)]  # parent not settled yet
    stem_joint = np.where(
        tree.stem_parent_node >= 0, carrier[np.maximum(tree.stem_parent_node, 0)], 0
    ).astype(np.int32)
    lj = (
        node_joints[tree.leaf_node, np.argmax(node_weights[tree.leaf_node], axis=1)]
        if tree.n_leaves
        else np.zeros(0, dtype=np.uint16)
    )

    # Hierarchy: previous joint on the chain, else the stem's attach joint; root = trunk base.
    js = s[joint_node]
    prev_node = joint_node - 1
    on_chain = (joint_node > tree.stem_node_start[js]) & has_prev[np.maximum(prev_node, 0)]
    parent = np.where(on_chain, joint_of[last_own[np.maximum(prev_node, 0)]], stem_joint[js])
    parent = parent.astype(np.int32)
    parent[0] = -1
    if J > 1 and not np.all(parent[1:] < np.arange(1, J)):
        raise ValueError("tree stems are not ordered parent before child")

    from scipy.spatial.transform import Rotation  # (0.2 s to import: only where used)

    if among is not None and frames is not None:  # LOD0's frames at the same nodes
        R = np.asarray(frames, dtype=np.float64)[np.searchsorted(among, tree.lod0_nodes[joint_node])]
    else:
        R = Rotation.from_matrix(tree.node_frame[joint_node]).as_matrix()  # orthonormalised
    t = tree.node_pos[joint_node]
    pr = np.maximum(parent, 0)
    local_R = np.einsum("jki,jkl->jil", R[pr], R)  # R_parent^T R
    local_t = np.einsum("jki,jk->ji", R[pr], t - t[pr])
    local_R[0], local_t[0] = R[0], t[0]
    world = np.zeros((J, 4, 4))
    world[:, :3, :3] = R
    world[:, :3, 3] = t
    world[:, 3, 3] = 1.0
    skeleton = Skeleton(
        names=joint_names(tree, joint_node, js),
        parent=parent,
        rest_translation=local_t,
        rest_rotation=Rotation.from_matrix(local_R).as_quat(),
        bind_world=world,
    )
    return Rig(
        skeleton=skeleton,
        joint_node=joint_node,
        joint_stem=js.astype(np.int32),
        node_joints=node_joints,
        node_weights=node_weights,
        leaf_joint=lj.astype(np.uint16),
        stem_joint=stem_joint,
    )
