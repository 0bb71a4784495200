"""Wind loads per joint: what the paper sums over each branch and its children, and the springs.

Drag areas and their moments, masses and their first and second moments (each joint's whole
subtree, about its pivot), and each joint's spring k = E·π r⁴/4 over the wood it bends, with the
load-bearing radius where a Weber–Penn radius is too thin to hold its load, and softened to the
stiffness its drawn sag implies where the species weeps (wind.py's model).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rig import Rig
from .shapes import flare_factor
from .skeleton import depth_levels
from .tree import Tree
from .wind_options import DEFAULTS, GRAVITY, WindOptions


@dataclass(frozen=True, eq=False)
class JointLoads:
    """Static per-joint quantities of the model (subtree sums about each joint)."""

    pivot: np.ndarray  # (J, 3) joint positions at rest
    direction: np.ndarray  # (J, 3) unit branch direction at the joint
    area: np.ndarray  # (J,) drag area Σ C_d·A of the joint's own load, m²
    area_moment: np.ndarray  # (J, 3) Σ C_d·A_i (x_i − pivot) of its own load
    mass: np.ndarray  # (J,) subtree mass, kg
    inertia: np.ndarray  # (J,) subtree second moment of mass about the joint, kg·m² (trace)
    first_moment: np.ndarray  # (J, 3) s = Σ m (x − pivot) over the subtree, kg·m
    second_moment: np.ndarray  # (J, 3, 3) S = Σ m (x − pivot)(x − pivot)ᵀ (+ rods' own), kg·m²
    radius: np.ndarray  # (J,) r used for the stiffness: max(node radius, load-bearing radius)
    stiffness: np.ndarray  # (J,) k = E / ∫ (M/M₀)² dz / (π r⁴/4), N·m/rad (weeping: ≥ M₀/Δφ)
    span: np.ndarray  # (J,) ℓ, m
    area_first: np.ndarray  # (J, 3) Σ C_d·A (x − pivot) over the subtree (aerodynamic damping)
    area_second: np.ndarray  # (J, 3, 3) Σ C_d·A (x − pivot)(x − pivot)ᵀ over the subtree


def _node_carrier(tree: Tree, rig: Rig, n_joints: int) -> np.ndarray:
    """Joint that carries each node: the nearest joint at or below it on its own stem, else the
    stem's attach joint (stems without joints of their own ride rigidly on their carrier)."""
    n = tree.n_nodes
    node_joint = np.full(n, -1, dtype=np.int64)
    node_joint[np.asarray(rig.joint_node, dtype=np.int64)] = np.arange(n_joints)
    marker = np.where(node_joint >= 0, np.arange(n), -1)
    last = np.maximum.accumulate(marker)
    own_start = np.asarray(tree.stem_node_start, dtype=np.int64)[tree.node_stem]
    attach = np.clip(np.asarray(rig.stem_joint, dtype=np.int64)[tree.node_stem], 0, n_joints - 1)
    return np.where(last >= own_start, node_joint[np.maximum(last, 0)], attach)


def _joint_span(tree: Tree, rig: Rig) -> np.ndarray:
    """ℓ: stem length from each joint's node to the next joint on its stem (or the stem tip)."""
    n = tree.n_nodes
    jn = np.asarray(rig.joint_node, dtype=np.int64)
    jointed = np.zeros(n, dtype=bool)
    jointed[jn] = True
    big = np.iinfo(np.int64).max
    first_at_or_after = np.minimum.accumulate(np.where(jointed, np.arange(n), big)[::-1])[::-1]
    after = np.append(first_at_or_after[1:], big)[jn]
    stem = tree.node_stem[jn]
    stem_last = (tree.stem_node_start + tree.stem_node_count - 1)[stem].astype(np.int64)
    end = np.where(after <= stem_last, after, stem_last)
    span = tree.node_z[end] - tree.node_z[jn]
    seg = tree.stem_length[stem] / np.maximum(tree.stem_node_count[stem] - 1, 1)
    return np.maximum(np.where(span > 1e-9, span, seg), 1e-3)


def load_bearing_radius(weight_moment: np.ndarray, options: WindOptions) -> np.ndarray:
    """Radius whose wood carries `weight_moment` (N·m) at the working stress σ_w:
    σ = M·r/I = 4M/(π r³) → r = (4M / (π σ_w))^(1/3) (constant-stress sizing, McMahon/Niklas).

    Why: Weber–Penn tapers stems to a point (nTaper 1 is a cone), so tip joints reach radii
    (0.3 mm) that no wood can hold a leafy branch with. The geometry stays as drawn; the spring
    keeps the radius law k = E·π r⁴/4 / ℓ, with the radius the wood would need where the drawn
    one is thinner. Where the drawn radius suffices (the trunk, most of the branches) nothing
    changes."""
    return np.cbrt(4.0 * np.maximum(weight_moment, 0.0) / (np.pi * options.working_stress))


def wood_radius(tree: Tree) -> np.ndarray:
    """Node radii without the trunk's flare: the buttress at the foot is short and stiff and
    does not bend the stem above it."""
    r = np.asarray(tree.node_radius, dtype=np.float64)
    trunk = tree.stem_level[tree.node_stem] == 0
    if not trunk.any():
        return r
    rel = tree.node_z / np.maximum(tree.stem_length[tree.node_stem], 1e-12)
    return np.where(trunk, r / flare_factor(tree.params.flare, rel), r)


def _moment_fraction(z: np.ndarray, L: np.ndarray, a: np.ndarray) -> np.ndarray:
    """M(z)/M(0): the moment a joint's load puts on its stem at distance z from the joint, the
    load spread evenly over [L − a, L + a] along the lever (L its centre)."""
    ramp = np.clip(L + a - z, 0.0, None) ** 2 / np.maximum(4.0 * a, 1e-12)
    beyond = np.where(z <= L - a, L - z, np.where(a > 0.0, ramp, 0.0))  # E[(x − z)⁺] / 1
    return beyond / L


def _span_compliance(
    tree: Tree, rig: Rig, carrier: np.ndarray, bearing: np.ndarray, lever: np.ndarray, spread: np.ndarray
) -> np.ndarray:
    """Per joint, the lumped hinge compliance of the wood it bends (its own stem from its node
    to the next joint): c = ∫ (M(z)/M(0))² dz / (π r⁴/4) (the span's bending energy, Castigliano),
    r linear between nodes and at least the joint's load-bearing radius; the load beyond the
    joint is spread evenly over [L − a, L + a] along the lever (L = |s|/m its centre, a from its
    second moment), so M(z) falls to zero past the load. 4-point Gauss per segment.

    Why: the paper turns each node by its radius; a joint standing for several segments bends
    as all of them do (series sum), but only as far as its load's moment reaches: a leafless tip
    whose radius tapers to nothing carries almost no moment where it is thin, so it no longer
    whips round, while a trunk span under the crown bends along its whole length."""
    n_j = rig.skeleton.parent.shape[0]
    seg = tree.segments
    joint = carrier[seg]
    own = np.asarray(rig.joint_stem)[joint] == tree.node_stem[seg]  # rigid stems bend nothing
    seg, joint = seg[own], joint[own]
    r = wood_radius(tree)
    z0 = tree.node_z[seg] - tree.node_z[np.asarray(rig.joint_node)[joint]]
    z1 = tree.node_z[seg + 1] - tree.node_z[np.asarray(rig.joint_node)[joint]]
    ell = np.linalg.norm(tree.node_pos[seg + 1] - tree.node_pos[seg], axis=1)
    t, wq = np.polynomial.legendre.leggauss(4)
    t, wq = 0.5 * (t + 1.0), 0.5 * wq
    rr = np.maximum(r[seg, None] + (r[seg + 1] - r[seg])[:, None] * t, bearing[joint, None])
    z = z0[:, None] + (z1 - z0)[:, None] * t
    L = np.maximum(lever[joint], 1e-6)[:, None]
    a = np.minimum(spread[joint], lever[joint])[:, None]
    w = _moment_fraction(z, L, a) ** 2
    per = ell * np.sum(wq * w / (0.25 * np.pi * np.maximum(rr, 1e-9) ** 4), axis=1)
    return np.bincount(joint, weights=per, minlength=n_j)


def weeping_levels(params) -> np.ndarray:
    """Bool per stem level: does the species draw this level hanging under its weight? A level
    ≥ 1 whose Curve and CurveBack both bend it down (≥ 0) by more in all than its random
    CurveV, or a level ≥ 2 that AttractionUp < 0 droops (the paper's weeping willow).
    Upturned, S-curved and randomly wandering levels (aspen, tupelo, oak, shave grass) and every
    trunk are drawn by growth, not by weight."""
    out = np.zeros(len(params.level), dtype=bool)
    for lev in range(1, len(params.level)):
        lp = params.level[lev]
        down = lp.curve >= 0.0 and lp.curve_back >= 0.0 and lp.curve + lp.curve_back > abs(lp.curve_v)
        out[lev] = down or (lev >= 2 and params.attraction_up < 0.0)
    return out


def _sag_compliance(
    tree: Tree,
    rig: Rig,
    carrier: np.ndarray,
    first_moment: np.ndarray,
    direction: np.ndarray,
    lever: np.ndarray,
    spread: np.ndarray,
    modulus: float,
) -> np.ndarray:
    """Per joint of a weeping level, the hinge compliance (× E, as `_span_compliance`) that lets
    its weight bend it as drawn: c = E·Δφ/M₀, M₀ the bending moment of the subtree's weight at
    the joint and Δφ = Σ (M(z)/M₀)·(turn · M̂₀) the drawn turn of its span toward that moment
    (each node's turn weighted by the share of M₀ still acting there). Only turns where the stem
    still rises count: below the horizontal the weight pulls along a hanging stem rather than
    bending it, and its drawn curve there is growth form (CurveBack), not sag. 0 elsewhere.

    Why: a weeping stem's rest shape is the equilibrium of its own weight, κ = M/EI_eff ⇒
    EI_eff = M/κ. Weber–Penn radii (Ratio, RatioPower) draw a willow's limbs 30 cm thick, and
    wood that thick would sag 15–50 times less than drawn (median 25); young, pendulous wood
    is that much more compliant than a solid rod of the drawn radius."""
    n_j = rig.skeleton.parent.shape[0]
    weeps = weeping_levels(tree.params)[tree.stem_level[np.asarray(rig.joint_stem)]]
    seg = tree.segments
    joint = carrier[seg]
    keep = (np.asarray(rig.joint_stem)[joint] == tree.node_stem[seg]) & weeps[joint]
    d0 = tree.node_frame[seg, :, 2]
    keep &= d0[:, 2] > 0.0  # the stem still rises
    seg, joint, d0 = seg[keep], joint[keep], d0[keep]
    d1 = tree.node_frame[seg + 1, :, 2]  # direction after the turn at the segment's far node
    axis = np.cross(d0, d1)
    sin = np.linalg.norm(axis, axis=1)
    turn = axis * (np.arctan2(sin, np.sum(d0 * d1, axis=1)) / np.maximum(sin, 1e-12))[:, None]
    # the weight's moment about each joint, g ẑ × s, without its twisting part
    moment = GRAVITY * np.cross(np.array([0.0, 0.0, 1.0]), first_moment)
    moment -= np.sum(moment * direction, axis=1, keepdims=True) * direction
    m0 = np.linalg.norm(moment, axis=1)
    unit = moment / np.maximum(m0, 1e-300)[:, None]
    z = tree.node_z[seg + 1] - tree.node_z[np.asarray(rig.joint_node)[joint]]
    share = _moment_fraction(z, np.maximum(lever[joint], 1e-6), np.minimum(spread[joint], lever[joint]))
    dphi = np.bincount(joint, weights=share * np.sum(turn * unit[joint], axis=1), minlength=n_j)
    sagging = weeps & (m0 > 0.0) & (dphi > 0.0)
    k = m0 / np.where(sagging, dphi, 1.0)
    # weight above the pivot topples it (gravity's stiffness −g·s_z): keep it standing with a
    # safety factor of 2 against that, as living stems do (McMahon 1973: trees stand at about a
    # quarter of their buckling height)
    k = np.maximum(k, 2.0 * GRAVITY * np.maximum(first_moment[:, 2], 0.0))
    return np.where(sagging, modulus / np.where(sagging, k, 1.0), 0.0)


def subtree_moments(
    owner: np.ndarray,
    rel: np.ndarray,
    weight: np.ndarray,
    rod: np.ndarray,
    u: np.ndarray,
    pivot: np.ndarray,
    parent: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Zeroth, first and second moments (J,), (J, 3), (J, 3, 3) of `weight` at offsets `rel`
    from their owner joint's pivot (plus rod terms rod·u uᵀ), summed over each joint's whole
    subtree about its own pivot: deepest level first, parallel-axis shift to the parent."""
    n_j = pivot.shape[0]

    def per_joint(w: np.ndarray) -> np.ndarray:
        return np.bincount(owner, weights=w, minlength=n_j)

    m = per_joint(weight)
    s = np.stack([per_joint(weight * rel[:, i]) for i in range(3)], axis=1)
    S = np.empty((n_j, 3, 3))
    for i in range(3):
        for k in range(i, 3):
            S[:, i, k] = S[:, k, i] = per_joint(weight * rel[:, i] * rel[:, k] + rod * u[:, i] * u[:, k])
    for idx in reversed(depth_levels(parent)[1:]):
        p = parent[idx]
        d = pivot[idx] - pivot[p]
        sd = np.einsum("ji,jk->jik", s[idx], d)
        np.add.at(
            S, p, S[idx] + sd + sd.transpose(0, 2, 1) + m[idx, None, None] * np.einsum("ji,jk->jik", d, d)
        )
        np.add.at(s, p, s[idx] + m[idx, None] * d)
        np.add.at(m, p, m[idx])
    return m, s, S


def joint_loads(tree: Tree, rig: Rig, options: WindOptions = DEFAULTS) -> JointLoads:
    """Drag areas, masses, mass moments and stiffnesses per joint (all vectorised)."""
    skel = rig.skeleton
    n_j = skel.parent.shape[0]
    pivot = np.asarray(skel.bind_world, dtype=np.float64)[:, :3, 3]
    direction = tree.node_frame[rig.joint_node][:, :, 2]
    direction = direction / np.linalg.norm(direction, axis=1, keepdims=True)
    carrier = _node_carrier(tree, rig, n_j)

    # wood: one frustum per segment (consecutive nodes of one stem), carried by its lower node
    seg = tree.segments
    a, b = tree.node_pos[seg], tree.node_pos[seg + 1]
    r0, r1 = tree.node_radius[seg], tree.node_radius[seg + 1]
    length = np.linalg.norm(b - a, axis=1)
    axis = (b - a) / np.maximum(length, 1e-12)[:, None]
    wood_mid = 0.5 * (a + b)
    wood_mass = options.wood_density * np.pi * length * (r0 * r0 + r0 * r1 + r1 * r1) / 3.0
    wood_area = options.stem_drag_coefficient * (r0 + r1) * length  # C_d · 2·r̄·l
    wood_joint = carrier[seg]

    # leaves: blade centroid, area, fresh mass; rigidly on rig.leaf_joint
    leaf_area = np.asarray(tree.leaf_area, dtype=np.float64)
    leaf_drag = options.drag_coefficient * leaf_area  # C_d · A
    leaf_mid = tree.leaf_middle
    leaf_mass = options.leaf_areal_density * leaf_area
    leaf_joint = np.asarray(rig.leaf_joint, dtype=np.int64)

    x = np.concatenate([wood_mid, leaf_mid])
    owner = np.concatenate([wood_joint, leaf_joint])
    mass = np.concatenate([wood_mass, leaf_mass])
    area = np.concatenate([wood_area, leaf_drag])
    rel = x - pivot[owner]

    own_area = np.bincount(owner, weights=area, minlength=n_j)
    own_moment = np.stack(
        [np.bincount(owner, weights=area * rel[:, i], minlength=n_j) for i in range(3)], axis=1
    )
    # rods: each wood segment's own second moment m·l²/12·u uᵀ (leaves are points)
    rod = np.concatenate([wood_mass * length**2 / 12.0, np.zeros_like(leaf_mass)])
    u = np.concatenate([axis, np.zeros_like(leaf_mid)])
    parent = np.asarray(skel.parent, dtype=np.int64)
    m_sub, s_sub, S_sub = subtree_moments(owner, rel, mass, rod, u, pivot, parent)
    rod_area = np.concatenate([wood_area * length**2 / 12.0, np.zeros_like(leaf_drag)])
    a_sub, as_sub, aS_sub = subtree_moments(owner, rel, area, rod_area, u, pivot, parent)

    span = _joint_span(tree, rig)
    # weight moment of the subtree held sideways (orientation-independent, the worst case)
    weight_moment = GRAVITY * np.linalg.norm(s_sub, axis=1)
    bearing = load_bearing_radius(weight_moment, options)
    radius = np.maximum(tree.node_radius[rig.joint_node], bearing)
    inertia = np.trace(S_sub, axis1=1, axis2=2)
    lever = np.linalg.norm(s_sub, axis=1) / np.maximum(m_sub, 1e-12)  # load centre's lever
    spread = np.sqrt(3.0 * np.maximum(inertia / np.maximum(m_sub, 1e-12) - lever**2, 0.0))
    compliance = _span_compliance(tree, rig, carrier, bearing, lever, spread)
    # a weeping stem is as compliant as its drawn sag says, never stiffer than its wood
    sag = _sag_compliance(tree, rig, carrier, s_sub, direction, lever, spread, options.elastic_modulus)
    compliance = np.maximum(compliance, sag)
    # a joint whose span has no length (a LOD's joint on a kept stem's base, where its parent's
    # sits) is rigid: a thousand times as stiff as the stiffest real joint, not infinitely (a
    # floor relative to the most compliant joint reached the willow's trunk: its strands are
    # hair-thin, and the trunk swayed at 0.1 Hz)
    positive = compliance[compliance > 0]
    floor = float(positive.min()) * 1e-3 if positive.size else 1e-300
    stiffness = options.stiffness * options.elastic_modulus / np.maximum(compliance, floor)
    stiffness = np.maximum(stiffness, 1e-9)  # a massless zero-radius joint must not divide by zero
    return JointLoads(
        pivot,
        direction,
        own_area,
        own_moment,
        m_sub,
        inertia,
        s_sub,
        S_sub,
        radius,
        stiffness,
        span,
        as_sub,
        aS_sub,
    )
