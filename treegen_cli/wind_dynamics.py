"""The tree as one linear system in its joints' bending angles, and its natural modes.

M θ̈ + C θ̇ + K θ = Q over the whole hierarchy (wind.py's model): mass and aerodynamic damping
as quadratic forms of every weight moving with its ancestors' joints, springs plus gravity's
geometric stiffness, solved once for the modes the bake and `info --wind` use.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.linalg import cholesky, solve_triangular

from .rig import Rig
from .skeleton import depth_levels
from .tree import Tree
from .wind_loads import JointLoads, _node_carrier, joint_loads
from .wind_options import AIR_DENSITY, DEFAULTS, GRAVITY, WindOptions


@dataclass(frozen=True, eq=False)
class Dynamics:
    """The tree as one linear system in the joints' bending angles (two per joint, about the
    axes perpendicular to the branch; no twist), and its natural modes.

    M θ̈ + C θ̇ + K θ = Q. θ_j are world-frame rotation vectors of each joint's deviation from
    rest (a point x carried by joint j moves by Σ_{a ∈ ancestors(j) ∪ {j}} θ_a × (x − p_a)).
    M: kinetic energy of every mass over the hierarchy (joint a and its descendant b share
    their mass through b's subtree). K: the springs E·π r⁴/4/ℓ plus gravity's second-order
    (geometric) stiffness — hanging strands swing back as pendulums, upright stems soften a
    little. C: the structural ζ plus the drag on every leaf and stem linearised in its own
    velocity (aerodynamic damping grows with the wind, so storms sway less about their lean),
    kept on the modes' diagonal."""

    basis: np.ndarray  # (J, 3, 2) bending axes per joint
    mass: np.ndarray  # (n, n), n = 2J
    stiffness: np.ndarray  # (n, n)
    omega: np.ndarray  # (n,) natural angular frequencies, rad/s, ascending
    modes: np.ndarray  # (n, n) mass-normalised mode shapes (columns)
    damping: np.ndarray  # (n,) ζ per mode: structural + aerodynamic


def _ancestor_pairs(parent: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(a, b) for every joint b and every a in ancestors(b) ∪ {b} (one numpy pass per level)."""
    n_j = parent.shape[0]
    anc = np.zeros((n_j, n_j), dtype=bool)
    for idx in depth_levels(parent):
        p = parent[idx]
        has = p >= 0
        anc[idx[has]] = anc[p[has]]
        anc[idx, idx] = True
    b, a = np.nonzero(anc)
    return a, b


def _bending_basis(loads: JointLoads) -> np.ndarray:
    """Two unit axes per joint perpendicular to the branch direction."""
    d = loads.direction
    helper = np.where(np.abs(d[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    e1 = np.cross(helper, d)
    e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
    e2 = np.cross(d, e1)
    return np.stack([e1, e2], axis=2)


def _skew_free_gravity(s: np.ndarray) -> np.ndarray:
    """g·(s ẑᵀ − s_z I): gravity's bilinear form between a joint and a descendant whose
    subtree has first moment s (about the descendant's pivot)."""
    out = np.zeros(s.shape[:-1] + (3, 3))
    out[..., :, 2] = s
    out -= s[..., 2, None, None] * np.eye(3)
    return GRAVITY * out


def _hierarchy_matrix(
    a: np.ndarray, b: np.ndarray, E: np.ndarray, s: np.ndarray, S: np.ndarray, pivot: np.ndarray
) -> np.ndarray:
    """(2J, 2J) quadratic form ½ θ̇ᵀ X θ̇ of a weight field moving with the joints (mass: kinetic
    energy; drag area: dissipation): X_ab = Σ_{i ∈ sub(b)} w [r_a×]ᵀ[r_b×]
    = (tr S_b + d·s_b) I − S_b − s_b dᵀ with r_a = r_b + d, d = p_b − p_a, a ancestor of b."""
    n_j = pivot.shape[0]
    d = pivot[b] - pivot[a]
    sb, Sb = s[b], S[b]
    x = (
        (np.trace(Sb, axis1=1, axis2=2) + np.einsum("ij,ij->i", d, sb))[:, None, None] * np.eye(3)
        - Sb
        - np.einsum("ji,jk->jik", sb, d)
    )
    return _assemble(a, b, np.swapaxes(E[a], 1, 2) @ x @ E[b], n_j)


def _assemble(a: np.ndarray, b: np.ndarray, blocks: np.ndarray, n_j: int) -> np.ndarray:
    """Symmetric (2J, 2J) matrix from its (a, b) blocks, a ancestor-or-self of b."""
    out = np.zeros((n_j, 2, n_j, 2))
    out[a, :, b, :] = blocks
    off = a != b
    out[b[off], :, a[off], :] = blocks[off].transpose(0, 2, 1)
    return out.reshape(2 * n_j, 2 * n_j)


def drag_damping_coefficient(options: WindOptions) -> float:
    """c per unit drag area (N·s/m³): the drag ½ρ s(|v|)|v|v linearised in the branch's own
    velocity about the mean wind U, ρ·s(U)·U·(1 + β/2), β = d ln s / d ln U (Vogel)."""
    u = options.speed
    x = (u / options.reconfig_speed) ** 2
    soften = (1.0 + x) ** (0.5 * options.vogel_exponent)
    beta = options.vogel_exponent * x / (1.0 + x)
    return AIR_DENSITY * soften * u * (1.0 + 0.5 * beta)


def dynamics(
    tree: Tree, rig: Rig, options: WindOptions = DEFAULTS, loads: JointLoads | None = None
) -> Dynamics:
    """Assemble M, K and the aerodynamic damping over the hierarchy and solve K φ = ω² M φ
    (dense, n = 2J ≤ 512); modal damping ζ_m = ζ + φ_mᵀ C_aero φ_m / (2 ω_m)."""
    ld = loads if loads is not None else joint_loads(tree, rig, options)
    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    n_j = parent.shape[0]
    E = _bending_basis(ld)
    a, b = _ancestor_pairs(parent)
    M = _hierarchy_matrix(a, b, E, ld.first_moment, ld.second_moment, ld.pivot)
    C = drag_damping_coefficient(options) * _hierarchy_matrix(
        a, b, E, ld.area_first, ld.area_second, ld.pivot
    )
    # gravity: K_ab (a strict ancestor of b) = g(s_b ẑᵀ − s_bz I); K_aa = its symmetric part
    g_ab = _skew_free_gravity(ld.first_moment[b])
    diag = a == b
    g_ab[diag] = 0.5 * (g_ab[diag] + g_ab[diag].transpose(0, 2, 1))
    K = _assemble(a, b, np.swapaxes(E[a], 1, 2) @ g_ab @ E[b], n_j)
    n = 2 * n_j
    # --stiffness scales the root plate with the wood (ld.stiffness has it): both in series,
    # scaling one left the rocking mode where it was (×4 moved 0.56 Hz to 0.70, not 1.1)
    K[np.arange(n), np.arange(n)] += np.repeat(_springs(ld, rig, options.stiffness * options.anchorage), 2)
    # massless joints (bare tips of synthetic rigs) get a tiny inertia so M stays definite
    M[np.diag_indices_from(M)] += 1e-9 * max(float(np.max(np.diag(M))), 1e-12)
    w2, phi = _modes(K, M)
    # a stem too thin for gravity would buckle; the load-bearing radius prevents it, the clamp
    # keeps degenerate inputs (zero modulus) finite
    w2 = np.maximum(w2, 1e-6 * max(float(w2.max(initial=0.0)), 1e-12))
    omega = np.sqrt(w2)
    zeta = options.damping_ratio + np.sum(phi * (C @ phi), axis=0) / (2.0 * omega)
    return Dynamics(E, M, K, omega, phi, zeta)


def _modes(K: np.ndarray, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """K φ = ω² M φ via Cholesky M = L Lᵀ and a symmetric eigenproblem (faster than LAPACK's
    generalized drivers here); φ mass-normalised (φᵀ M φ = I)."""
    if M.shape[0] == 0:
        return np.zeros(0), np.zeros((0, 0))
    L = cholesky(M, lower=True)
    a = solve_triangular(L, solve_triangular(L, K, lower=True).T, lower=True)
    w2, v = np.linalg.eigh(0.5 * (a + a.T))
    return w2, solve_triangular(L.T, v, lower=False)


def _springs(loads: JointLoads, rig: Rig, anchorage: float) -> np.ndarray:
    """Spring per joint; a root joint (the trunk base) also has the root plate in series,
    1/k = 1/k_wood + 1/(anchorage · tree mass): trees rock on their roots as well as bend."""
    k = loads.stiffness.copy()
    root = np.asarray(rig.skeleton.parent) < 0
    k[root] = 1.0 / (1.0 / k[root] + 1.0 / np.maximum(anchorage * loads.mass[root], 1e-12))
    return k


def trunk_top(tree: Tree, rig: Rig) -> tuple[int, np.ndarray]:
    """(joint, rest position) of the trunk's tip: the last node of stem 0, carried by the last
    trunk joint."""
    tip = int(tree.stem_node_start[0] + tree.stem_node_count[0] - 1)
    carrier = _node_carrier(tree, rig, rig.skeleton.parent.shape[0])
    return int(carrier[tip]), tree.node_pos[tip]


def displacement_map(
    dyn: Dynamics, loads: JointLoads, parent: np.ndarray, joint: int, point: np.ndarray
) -> np.ndarray:
    """D (3, 2J): small-angle displacement of `point`, carried by `joint`, per bending angle."""
    n_j = parent.shape[0]
    D = np.zeros((3, n_j, 2))
    a = joint
    while a >= 0:
        r = point - loads.pivot[a]
        D[:, a, :] = -np.cross(r[None, :], dyn.basis[a].T).T  # θ × r = −r × θ
        a = int(parent[a])
    return D.reshape(3, 2 * n_j)
