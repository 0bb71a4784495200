"""LODs sway as LOD0 does: LOD0's wind bends carried over to a LOD's own rig.

    theta_k = lod_angles(theta0, tree0, rig0, tree_k, rig_k)   # (J_k, n, 3) from (J0, n, 3)

Baked from its own thinned leaves and pruned rig, a LOD moved unlike the tree it stands in for:
the aspen's LOD1 leaned 30 % less than LOD0 (its twigs, and their joints, gone) and the crown's
top jumped 5.7 px at the switch (the tupelo's 4.4 px at its second), a pop in motion that the
rest-pose silhouettes (silhouette.py) do not see (bench/lod_motion_bench.py). Here a LOD's bends
are the ones that move the points it draws (leaf middles, branch nodes) as LOD0 moves them, in
the least-squares sense, on the small-angle model the wind is solved in: a point p carried by
joints a moves by Σ_a θ_a × (p − pivot_a), each θ_a a bend about the two axes across its bone
(no twist, as wind_dynamics). The map from LOD0's bends to the LOD's is one linear solve
(2J × 2J), applied to every frame at once; the caller bounds the result as LOD0's (bound_bends).

Leaves weigh by their area (what the eye follows), nodes by their bark's; a LOD leaf moves like
the nearest of LOD0's (lod_leaves.gather_leaves put it among those it stands for), a node like
itself (LOD nodes are LOD0's: Tree.lod0_nodes). Every joint is also pulled, with a weight
REGULARISE of the fit's mean, towards the turn LOD0 gives its node: joints the sampled points
hardly move (bare, near the trunk's base) follow that instead of wandering.
"""

from __future__ import annotations

import numpy as np

from .rig import Rig
from .skeleton import depth_levels, joint_depth
from .tree import Tree
from .wind import from_axes, in_axes, one_blas_thread

MAX_POINTS = 2000  # leaves (and as many nodes) sampled, at most: the fit needs shape, not all
NEAR_POINTS = 50_000  # LOD0's leaves searched for a LOD leaf's nearest, at most
REGULARISE = 1e-3  # weight of the pull towards each node's own turn, × the fit's mean diagonal


class Nearest:
    """LOD0's leaf look-up (a KD-tree of a sample of its leaves), built on first use and kept
    for the next LOD. (A LOD's nodes name their LOD0 node: Tree.lod0_nodes.)"""

    def __init__(self) -> None:
        self._cache: dict[str, object] = {}

    def leaves(self, tree0: Tree) -> tuple[object, np.ndarray]:
        if "leaves" not in self._cache:
            from scipy.spatial import cKDTree

            some = _stride(tree0.n_leaves, NEAR_POINTS)
            self._cache["leaves"] = (cKDTree(_middles(tree0, some)), some)
        return self._cache["leaves"]  # type: ignore[return-value]


@one_blas_thread  # the same bytes in any process (see wind.one_blas_thread)
def lod_angles(
    theta0: np.ndarray, tree0: Tree, rig0: Rig, tree: Tree, rig: Rig, near: Nearest | None = None
) -> np.ndarray:
    """Bends (J, n, 3) for `rig` (on `tree`, a LOD cut from `tree0`) that move the LOD's points
    as `theta0` (J0, n, 3) on `rig0` moves them in LOD0 (see the module doc); unbounded."""
    from scipy.linalg import cho_factor, cho_solve

    J0, n = theta0.shape[:2]
    J = len(rig.skeleton.parent)
    if J == 0 or n == 0 or not np.any(theta0):
        return np.zeros((J, n, 3))
    near = near if near is not None else Nearest()
    # leaves take part where LOD0 has leaves to move them by (a leafless tree: its nodes only)
    leaves = _stride(tree.n_leaves if tree0.n_leaves else 0)
    nodes = _stride(tree.n_nodes)
    # LOD nodes are LOD0's (lod_leaves.prune_stems, lod_nodes.coarsen_nodes copy them)
    node0, joint_node0 = tree.lod0_nodes[nodes], tree.lod0_nodes[rig.joint_node]
    mid = _middles(tree, leaves)
    zero = np.zeros(len(leaves), dtype=np.int64)
    leaf0 = zero
    if len(leaves):  # among a sample of LOD0's leaves: same twigs, same joints
        index, some = near.leaves(tree0)
        leaf0 = some[index.query(mid)[1]]
    pts = np.concatenate([mid, tree.node_pos[nodes]])
    area = tree.leaf_size[leaves, 0] * tree.leaf_size[leaves, 1]
    w = np.concatenate([area, 2.0 * tree.node_radius[nodes] * _node_length(tree)[nodes]])
    ones = np.c_[np.ones(len(leaves)), zero]
    carry = np.concatenate([np.c_[rig.leaf_joint[leaves], zero], rig.node_joints[nodes]]).astype(np.int64)
    cw = np.concatenate([ones, rig.node_weights[nodes]])
    carry0 = np.concatenate([np.c_[rig0.leaf_joint[leaf0], zero], rig0.node_joints[node0]]).astype(np.int64)
    cw0 = np.concatenate([ones, rig0.node_weights[node0]])
    E = np.asarray(rig.skeleton.bind_world)[:, :3, :2]  # the two axes across each bone
    G = _chain_matrix(pts, carry, cw, rig) @ _across(E)  # (3P, 2J): LOD bends → point motion
    H = _chain_matrix(pts, carry0, cw0, rig0)  # (3P, 3J0): LOD0 bends → the same points' motion
    W = np.repeat(w / max(float(w.mean()), 1e-30), 3)
    GtW = G.T.multiply(W).tocsr()
    A = (GtW @ G).toarray()
    B = (GtW @ H).toarray()
    lam = REGULARISE * max(float(np.trace(A)) / max(2 * J, 1), 1e-12)
    own = in_axes(E, _node_turns(theta0, rig0, rig, joint_node0))  # (J, 2, n)
    rhs = B @ theta0.transpose(0, 2, 1).reshape(3 * J0, n) + lam * own.reshape(2 * J, n)
    a = cho_solve(cho_factor(A + lam * np.eye(2 * J)), rhs).reshape(J, 2, n)
    return from_axes(E, a)


def _across(E: np.ndarray):
    """Sparse block diagonal (3J, 2J) of the per-joint bases E (J, 3, 2): bend → rotation vector."""
    from scipy.sparse import coo_matrix

    J = len(E)
    i, k = np.meshgrid(np.arange(3), np.arange(2), indexing="ij")
    rows = (3 * np.arange(J)[:, None, None] + i).reshape(-1)
    cols = (2 * np.arange(J)[:, None, None] + k).reshape(-1)
    return coo_matrix((E.reshape(-1), (rows, cols)), shape=(3 * J, 2 * J)).tocsr()


def _stride(count: int, most: int | None = None) -> np.ndarray:
    """Every k-th of `count` items, at most `most` (MAX_POINTS; deterministic)."""
    step = max(1, -(-count // (most or MAX_POINTS)))
    return np.arange(0, count, step)


def _middles(tree: Tree, which: np.ndarray) -> np.ndarray:
    """Tree.leaf_middle of the leaves `which` only (a willow has 300,000)."""
    size, frame = tree.leaf_size[which, 0], tree.leaf_frame[which, :, 1]
    return tree.leaf_pos[which] + (0.5 * size)[:, None] * frame


def _node_length(tree: Tree) -> np.ndarray:
    """(N,) length of the segment from each node to the next on its stem (0 at a stem's tip)."""
    out = np.zeros(tree.n_nodes)
    seg = tree.segments
    out[seg] = np.linalg.norm(tree.node_pos[seg + 1] - tree.node_pos[seg], axis=1)
    return out


def _ancestors(parent: np.ndarray) -> np.ndarray:
    """(J, D) each joint and its ancestors, root last, padded with −1."""
    D = int(joint_depth(parent).max(initial=0)) + 1
    out = np.full((len(parent), D), -1, dtype=np.int64)
    out[:, 0] = np.arange(len(parent))
    for d in range(1, D):
        prev = out[:, d - 1]
        out[:, d] = np.where(prev >= 0, parent[np.maximum(prev, 0)], -1)
    return out


def _chain_matrix(points: np.ndarray, carry: np.ndarray, weight: np.ndarray, rig: Rig):
    """Sparse (3P, 3J): the small-angle motion of each point (carried by the joints `carry`
    (P, 2) blended by `weight`) per bend of every joint: −w [p − pivot_a]ₓ for each ancestor a."""
    from scipy.sparse import coo_matrix

    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    J = len(parent)
    pivot = np.asarray(rig.skeleton.bind_world)[:, :3, 3]
    anc = _ancestors(parent)
    P = len(points)
    rows, cols, vals = [], [], []
    for k in range(carry.shape[1]):
        a = anc[carry[:, k]]  # (P, D)
        ok = (a >= 0) & (weight[:, k, None] != 0.0)
        p_idx, d_idx = np.nonzero(ok)
        joint = a[p_idx, d_idx]
        r = points[p_idx] - pivot[joint]
        wk = weight[p_idx, k]
        skew = np.zeros((len(joint), 3, 3))  # d = θ × r = −[r]ₓ θ
        skew[:, 0, 1], skew[:, 0, 2] = r[:, 2], -r[:, 1]
        skew[:, 1, 0], skew[:, 1, 2] = -r[:, 2], r[:, 0]
        skew[:, 2, 0], skew[:, 2, 1] = r[:, 1], -r[:, 0]
        i, j = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        rows.append((3 * p_idx[:, None, None] + i).reshape(-1))
        cols.append((3 * joint[:, None, None] + j).reshape(-1))
        vals.append((wk[:, None, None] * skew).reshape(-1))
    return coo_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(3 * P, 3 * J)
    ).tocsr()


def _node_turns(theta0, rig0: Rig, rig: Rig, at: np.ndarray) -> np.ndarray:
    """Bends (J, n, 3) that give each LOD joint frame the turn LOD0 gives its node (`at`, in
    LOD0's tree: the skin's blend of the jointed nodes around it), less its parent's."""
    parent0 = np.asarray(rig0.skeleton.parent, dtype=np.int64)
    total0 = theta0.copy()
    for idx in depth_levels(parent0)[1:]:
        total0[idx] += total0[parent0[idx]]
    j, w = rig0.node_joints[at].astype(np.int64), rig0.node_weights[at].astype(np.float64)
    total = w[:, 0, None, None] * total0[j[:, 0]] + w[:, 1, None, None] * total0[j[:, 1]]
    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    out = total.copy()
    for idx in depth_levels(parent)[1:]:
        out[idx] -= total[parent[idx]]
    return out
