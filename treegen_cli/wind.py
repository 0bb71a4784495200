"""Wind: a seeded, periodic wind field and the paper's per-joint spring model, baked into a Clip.

Result: Tree + Rig → Clip "wind" with (fps·duration + 1, J, 4) local quaternions (xyzw);
key 0 == key K−1 (seamless loop), speed 0 → rest exactly.

    clip = bake_wind(tree, rig, WindOptions(speed=6.0, direction_deg=90), seed=7)

The model (Kondo et al., after Weber–Penn; REFERENCE.md §1, §3):

* Loads, as the paper: the wind on the leaves F = W·A (W = ½·ρ_air·|v|·v, softened at high speed by
  Vogel's reconfiguration) plus cylinder drag on the wood; weight F_g = G·(l·π r²·d + A·A_g) as
  mass. Forces, masses and their moments are summed over each joint's whole subtree.
* Coupled dynamics: the joints are one linear system M θ̈ + C θ̇ + K θ = Q in two bending angles
  per joint (world axes perpendicular to the branch, no twist). M is the kinetic energy of every
  leaf and wood segment moving with all of its ancestors' joints; K the springs plus gravity's
  geometric stiffness (hanging strands swing back as pendulums); C a structural ζ plus the drag
  linearised in the branch's own velocity (aerodynamic damping, grows with the wind). Solved by
  its natural modes, K φ = ω² M φ: the trunk's sway mode falls out of the whole tree's masses.
* Springs from the node radius, k = E·π r⁴/4 over the wood the joint bends (the series sum of its
  segments, weighted by the square of the moment its load puts there, Castigliano). Where a
  Weber–Penn radius is thinner than wood that could hold its load (cone tapers reach 0.3 mm
  under a leafy twig), the radius is the load-bearing one at the wood's working stress
  (σ = 4M/πr³); the drawn geometry is unchanged. The trunk-base joint also rocks on the root
  plate (anchorage, in series), so the trunk bends from the ground up, without an elbow.
* Periodic steady state, exactly: the wind uses only harmonics of 1/duration, so the loads are
  periodic on the clip's grid; each harmonic's modal response is φᵀQ̂ / (ω_m² − ω² + 2iζ_mω_mω).
  The inverse rFFT is the motion after all transients have died out — it loops with continuous
  derivatives and needs no spin-up period.
* Gusts are log-normal along the wind (never reversing it). Large motion is bounded softly
  (b·tanh(|x|/b)): first each joint frame's world-space turn summed down its chain (so chains
  stream downwind instead of folding over), then each joint's own turn.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass, replace

import numpy as np
from scipy.linalg import cholesky, solve_triangular
from threadpoolctl import ThreadpoolController
from scipy.spatial.transform import Rotation

from .asset import Clip
from .clip import loop_times
from .errors import OptionError, TreegenError
from .quat import mul as quat_mul, unit as quat_unit
from .rig import Rig
from .shapes import flare_factor
from .skeleton import depth_levels
from .tree import Tree

AIR_DENSITY = 1.2          # kg/m³ at sea level, 20 °C
GRAVITY = 9.81             # m/s²
LATERAL_RATIO = 0.75       # σ_v / σ_u (lateral vs longitudinal gust; ESDU / ASCE ~0.75–0.88)
VERTICAL_RATIO = 0.5       # σ_w / σ_u


@dataclass(frozen=True)
class WindOptions:
    """Wind and wood parameters. Defaults: a pleasant 4 m/s breeze looping every 10 s."""

    speed: float = 4.0               # mean wind speed, m/s (Beaufort 3: 3.4–5.4)
    direction_deg: float = 0.0       # wind blows towards this azimuth; 0 = +X, 90 = +Y (Z up)
    gust: float = 0.35               # σ of the coherent gust process / mean speed
    turbulence: float = 0.3          # σ of the spatially varying part / mean speed
    duration: float = 10.0           # clip length = wind period, s (long enough not to notice)
    fps: float = 30.0                # keys per second
    wood_density: float = 800.0      # kg/m³, green (living) wood is ~800; dry ~500–700
    leaf_areal_density: float = 0.2  # kg/m², fresh leaf mass per area (dry LMA ~0.05–0.1, ~60% water)
    drag_coefficient: float = 0.15   # C_d per one-sided leaf area at low speed; crown sheltering
                                     # included (whole crowns: ~0.5 of frontal ≈ 0.1–0.2 of leaf area)
    vogel_exponent: float = -0.5     # B: leaves streamline, drag ∝ |v|^(2+B) above reconfig_speed
    reconfig_speed: float = 2.0      # m/s, where reconfiguration sets in
    stem_drag_coefficient: float = 1.2  # cylinder C_d on the wood's 2·r·l; 0 = the paper's leaves only
    elastic_modulus: float = 6.0e9   # Pa, green wood (Wood Handbook: 5.4–7.1 GPa for the paper's
                                     # aspen, tupelo, willow and oak)
    anchorage: float = 1500.0        # N·m/rad per kg of tree: root-plate rotational stiffness
                                     # (winching tests: ~150 N·m/kg turning moment at ~0.1 rad)
    stiffness: float = 1.0           # multiplier on every spring (artist's knob: f ∝ √stiffness)
    working_stress: float = 10.0e6   # Pa, bending stress wood holds its own weight at (green
                                     # modulus of rupture ~40 MPa over a safety factor ~4)
    damping_ratio: float = 0.15      # structural ζ of every mode (drag adds aerodynamic ζ; trees in leaf
                                     # measure ~0.05–0.2)
    max_bend_deg: float = 60.0       # soft bound on any joint frame's world-space turn from rest
    max_angle_deg: float = 40.0      # soft bound on any joint's own deviation from rest
    gust_length: float = 80.0        # m, integral length scale of the gusts (von Kármán; ESDU 85020:
                                     # ~50–150 m at 10–30 m height in open country)
    turbulence_length: float = 3.0   # m, integral length scale of the canopy turbulence
    incoherent: float = 0.3          # share of the turbulence variance that is per-branch noise
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)  # tree position in the shared field, m
    field_seed: int | None = None    # seed of the shared (advected) field; None: the tree's seed

    def __post_init__(self) -> None:
        for name, (lo, hi, unit) in _RANGES.items():
            value = getattr(self, name)
            if not (np.isfinite(value) and lo <= value <= hi):
                raise OptionError(name, value, f"allowed range {lo:g}..{hi:g} {unit}".rstrip(),
                                  f"WindOptions.{name}")
        for name in ("duration", "fps", "elastic_modulus", "stiffness", "working_stress", "anchorage",
                     "max_angle_deg", "max_bend_deg", "gust_length", "turbulence_length"):
            if getattr(self, name) <= 0:
                lo, hi, unit = _RANGES.get(name, (0.0, np.inf, ""))
                raise OptionError(name, getattr(self, name),
                                  f"must be > 0; allowed range (0, {hi:g}] {unit}".rstrip(),
                                  f"WindOptions.{name}")
        if len(self.origin) != 3 or not np.all(np.isfinite(self.origin)):
            raise TreegenError(f"wind option 'origin' must be three finite numbers, got {self.origin!r}")


_RANGES = {
    "speed": (0.0, 100.0, "m/s"),
    "direction_deg": (-360.0, 360.0, "degrees"),
    "gust": (0.0, 2.0, ""),
    "turbulence": (0.0, 2.0, ""),
    "duration": (0.0, 600.0, "s"),
    "fps": (0.0, 240.0, "1/s"),
    "wood_density": (1.0, 2000.0, "kg/m³"),
    "leaf_areal_density": (0.0, 5.0, "kg/m²"),
    "drag_coefficient": (0.0, 3.0, ""),
    "vogel_exponent": (-1.5, 0.0, ""),
    "reconfig_speed": (0.1, 100.0, "m/s"),
    "stem_drag_coefficient": (0.0, 3.0, ""),
    "elastic_modulus": (0.0, 1.0e12, "Pa"),
    "stiffness": (0.0, 1000.0, ""),
    "anchorage": (0.0, 1.0e9, "N·m/rad/kg"),
    "working_stress": (0.0, 1.0e9, "Pa"),
    "damping_ratio": (0.001, 10.0, ""),
    "max_angle_deg": (0.0, 90.0, "degrees"),
    "max_bend_deg": (0.0, 90.0, "degrees"),
    "gust_length": (0.0, 1000.0, "m"),
    "turbulence_length": (0.0, 1000.0, "m"),
    "incoherent": (0.0, 1.0, ""),
}

DEFAULTS = WindOptions()


# ---------------------------------------------------------------------------------------------
# loads per joint

@dataclass(frozen=True, eq=False)
class JointLoads:
    """Static per-joint quantities of the model (subtree sums about each joint)."""

    pivot: np.ndarray        # (J, 3) joint positions at rest
    direction: np.ndarray    # (J, 3) unit branch direction at the joint
    area: np.ndarray         # (J,) drag area Σ C_d·A of the joint's own load, m²
    area_moment: np.ndarray  # (J, 3) Σ C_d·A_i (x_i − pivot) of its own load
    mass: np.ndarray         # (J,) subtree mass, kg
    inertia: np.ndarray      # (J,) subtree second moment of mass about the joint, kg·m² (trace)
    first_moment: np.ndarray   # (J, 3) s = Σ m (x − pivot) over the subtree, kg·m
    second_moment: np.ndarray  # (J, 3, 3) S = Σ m (x − pivot)(x − pivot)ᵀ (+ rods' own), kg·m²
    radius: np.ndarray       # (J,) r used for the stiffness: max(node radius, load-bearing radius)
    stiffness: np.ndarray    # (J,) k = E / ∫ (M/M₀)² dz / (π r⁴/4), N·m/rad
    span: np.ndarray         # (J,) ℓ, m
    area_first: np.ndarray   # (J, 3) Σ C_d·A (x − pivot) over the subtree (aerodynamic damping)
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


def _span_compliance(tree: Tree, rig: Rig, carrier: np.ndarray, bearing: np.ndarray,
                     lever: np.ndarray, spread: np.ndarray) -> np.ndarray:
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
    seg = np.flatnonzero(tree.node_stem[:-1] == tree.node_stem[1:])
    joint = carrier[seg]
    own = np.asarray(rig.joint_stem)[joint] == tree.node_stem[seg]     # rigid stems bend nothing
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
    ramp = np.clip(L + a - z, 0.0, None) ** 2 / np.maximum(4.0 * a, 1e-12)
    beyond = np.where(z <= L - a, L - z, np.where(a > 0.0, ramp, 0.0))   # E[(x − z)⁺] / 1
    w = (beyond / L) ** 2
    per = ell * np.sum(wq * w / (0.25 * np.pi * np.maximum(rr, 1e-9) ** 4), axis=1)
    return np.bincount(joint, weights=per, minlength=n_j)


def subtree_moments(owner: np.ndarray, rel: np.ndarray, weight: np.ndarray, rod: np.ndarray,
                    u: np.ndarray, pivot: np.ndarray, parent: np.ndarray
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
        np.add.at(S, p, S[idx] + sd + sd.transpose(0, 2, 1) + m[idx, None, None] * np.einsum("ji,jk->jik", d, d))
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
    seg = np.flatnonzero(tree.node_stem[:-1] == tree.node_stem[1:])
    a, b = tree.node_pos[seg], tree.node_pos[seg + 1]
    r0, r1 = tree.node_radius[seg], tree.node_radius[seg + 1]
    length = np.linalg.norm(b - a, axis=1)
    axis = (b - a) / np.maximum(length, 1e-12)[:, None]
    wood_mid = 0.5 * (a + b)
    wood_mass = options.wood_density * np.pi * length * (r0 * r0 + r0 * r1 + r1 * r1) / 3.0
    wood_area = options.stem_drag_coefficient * (r0 + r1) * length      # C_d · 2·r̄·l
    wood_joint = carrier[seg]

    # leaves: blade centroid, area, fresh mass; rigidly on rig.leaf_joint
    leaf_area = np.asarray(tree.leaf_area, dtype=np.float64)
    leaf_drag = options.drag_coefficient * leaf_area                       # C_d · A
    leaf_mid = tree.leaf_pos + 0.5 * tree.leaf_size[:, :1] * tree.leaf_frame[:, :, 1]
    leaf_mass = options.leaf_areal_density * leaf_area
    leaf_joint = np.asarray(rig.leaf_joint, dtype=np.int64)

    x = np.concatenate([wood_mid, leaf_mid])
    owner = np.concatenate([wood_joint, leaf_joint])
    mass = np.concatenate([wood_mass, leaf_mass])
    area = np.concatenate([wood_area, leaf_drag])
    rel = x - pivot[owner]

    own_area = np.bincount(owner, weights=area, minlength=n_j)
    own_moment = np.stack([np.bincount(owner, weights=area * rel[:, i], minlength=n_j)
                           for i in range(3)], axis=1)
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
    lever = np.linalg.norm(s_sub, axis=1) / np.maximum(m_sub, 1e-12)     # load centre's lever
    spread = np.sqrt(3.0 * np.maximum(inertia / np.maximum(m_sub, 1e-12) - lever**2, 0.0))
    compliance = _span_compliance(tree, rig, carrier, bearing, lever, spread)
    # a joint whose span has no length (a LOD's joint on a kept stem's base, where its parent's
    # sits) is rigid: a thousand times as stiff as the stiffest real joint, not infinitely (a
    # floor relative to the most compliant joint reached the willow's trunk: its strands are
    # hair-thin, and the trunk swayed at 0.1 Hz)
    positive = compliance[compliance > 0]
    floor = float(positive.min()) * 1e-3 if positive.size else 1e-300
    stiffness = options.stiffness * options.elastic_modulus / np.maximum(compliance, floor)
    stiffness = np.maximum(stiffness, 1e-9)   # a massless zero-radius joint must not divide by zero
    return JointLoads(pivot, direction, own_area, own_moment, m_sub, inertia, s_sub, S_sub,
                      radius, stiffness, span, as_sub, aS_sub)


# ---------------------------------------------------------------------------------------------
# the coupled linear system

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

    basis: np.ndarray        # (J, 3, 2) bending axes per joint
    mass: np.ndarray         # (n, n), n = 2J
    stiffness: np.ndarray    # (n, n)
    omega: np.ndarray        # (n,) natural angular frequencies, rad/s, ascending
    modes: np.ndarray        # (n, n) mass-normalised mode shapes (columns)
    damping: np.ndarray      # (n,) ζ per mode: structural + aerodynamic


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


def _hierarchy_matrix(a: np.ndarray, b: np.ndarray, E: np.ndarray, s: np.ndarray,
                      S: np.ndarray, pivot: np.ndarray) -> np.ndarray:
    """(2J, 2J) quadratic form ½ θ̇ᵀ X θ̇ of a weight field moving with the joints (mass: kinetic
    energy; drag area: dissipation): X_ab = Σ_{i ∈ sub(b)} w [r_a×]ᵀ[r_b×]
    = (tr S_b + d·s_b) I − S_b − s_b dᵀ with r_a = r_b + d, d = p_b − p_a, a ancestor of b."""
    n_j = pivot.shape[0]
    d = pivot[b] - pivot[a]
    sb, Sb = s[b], S[b]
    x = ((np.trace(Sb, axis1=1, axis2=2) + np.einsum("ij,ij->i", d, sb))[:, None, None] * np.eye(3)
         - Sb - np.einsum("ji,jk->jik", sb, d))
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


def dynamics(tree: Tree, rig: Rig, options: WindOptions = DEFAULTS,
             loads: JointLoads | None = None) -> Dynamics:
    """Assemble M, K and the aerodynamic damping over the hierarchy and solve K φ = ω² M φ
    (dense, n = 2J ≤ 512); modal damping ζ_m = ζ + φ_mᵀ C_aero φ_m / (2 ω_m)."""
    ld = loads if loads is not None else joint_loads(tree, rig, options)
    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    n_j = parent.shape[0]
    E = _bending_basis(ld)
    a, b = _ancestor_pairs(parent)
    M = _hierarchy_matrix(a, b, E, ld.first_moment, ld.second_moment, ld.pivot)
    C = drag_damping_coefficient(options) * _hierarchy_matrix(a, b, E, ld.area_first,
                                                              ld.area_second, ld.pivot)
    # gravity: K_ab (a strict ancestor of b) = g(s_b ẑᵀ − s_bz I); K_aa = its symmetric part
    g_ab = _skew_free_gravity(ld.first_moment[b])
    diag = a == b
    g_ab[diag] = 0.5 * (g_ab[diag] + g_ab[diag].transpose(0, 2, 1))
    K = _assemble(a, b, np.swapaxes(E[a], 1, 2) @ g_ab @ E[b], n_j)
    n = 2 * n_j
    K[np.arange(n), np.arange(n)] += np.repeat(_springs(ld, rig, options.anchorage), 2)
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


def displacement_map(dyn: Dynamics, loads: JointLoads, parent: np.ndarray, joint: int,
                     point: np.ndarray) -> np.ndarray:
    """D (3, 2J): small-angle displacement of `point`, carried by `joint`, per bending angle."""
    n_j = parent.shape[0]
    D = np.zeros((3, n_j, 2))
    a = joint
    while a >= 0:
        r = point - loads.pivot[a]
        D[:, a, :] = -np.cross(r[None, :], dyn.basis[a].T).T      # θ × r = −r × θ
        a = int(parent[a])
    return D.reshape(3, 2 * n_j)


def trunk_mode(tree: Tree, rig: Rig, options: WindOptions = DEFAULTS,
               loads: JointLoads | None = None, dyn: Dynamics | None = None) -> int:
    """Index of the mode that carries most of the trunk top's static downwind deflection under
    the mean wind: the tree's sway mode (lower modes may be single hanging branches)."""
    ld = loads if loads is not None else joint_loads(tree, rig, options)
    dyn = dyn if dyn is not None else dynamics(tree, rig, options, ld)
    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    steady = replace(options, speed=max(options.speed, 1.0), gust=0.0, turbulence=0.0)
    torque = generalized_forces(tree, rig, steady, 0, 1, ld)[:, 0]
    Q = np.einsum("jca,jc->ja", dyn.basis, torque).reshape(-1)
    j, x = trunk_top(tree, rig)
    phi = np.deg2rad(options.direction_deg)
    e_dir = np.array([np.cos(phi), np.sin(phi), 0.0])
    along = e_dir @ displacement_map(dyn, ld, parent, j, x)
    share = (along @ dyn.modes) * (Q @ dyn.modes) / dyn.omega**2
    return int(np.argmax(share))


# ---------------------------------------------------------------------------------------------
# wind field

def _von_karman(f: np.ndarray, length: float, speed: float, lateral: bool) -> np.ndarray:
    """Von Kármán one-sided spectrum shape (unit variance) at frequencies f (Hz)."""
    n = f * length / speed
    if not lateral:
        return 4.0 * (length / speed) / (1.0 + 70.8 * n * n) ** (5.0 / 6.0)
    return 4.0 * (length / speed) * (1.0 + 755.2 * n * n) / (1.0 + 283.2 * n * n) ** (11.0 / 6.0)


def _amplitudes(n_bins: int, n_max: int, duration: float, sigma: float, length: float,
                speed: float, lateral: bool) -> np.ndarray:
    """Cosine amplitudes of harmonics 0..n_bins−1 (only 1..n_max nonzero) sampling the spectrum
    at its own level, a_b² / 2 = σ²·S(f_b)·Δf with Δf = 1/duration.

    Why: gusts slower than the loop cannot repeat within it; they would only change the clip's
    mean. Squeezing their variance into the resolvable band (as before) doubled the energy
    near a tree's resonance and swung crowns upwind in lulls."""
    amp = np.zeros(n_bins)
    if n_max < 1 or sigma <= 0.0:
        return amp
    f = np.arange(1, n_max + 1) / duration
    s = _von_karman(f, length, speed, lateral)
    amp[1:n_max + 1] = np.sqrt(2.0 * s / duration) * sigma
    return amp


def _series(amp: np.ndarray, phase: np.ndarray, delay: np.ndarray, duration: float,
            n: int) -> np.ndarray:
    """Real periodic signals (P, n) with cosine amplitudes `amp` (B,), phases (P|1, B) delayed by
    `delay` (P,) seconds: Σ a_b cos(2π f_b (t − delay) + φ_b), evaluated by inverse rFFT."""
    f = np.arange(amp.shape[0]) / duration
    coef = (0.5 * n) * amp[None, :] * np.exp(1j * (phase - 2.0 * np.pi * f[None, :] * delay[:, None]))
    return np.fft.irfft(coef, n=n, axis=1)


def wind_velocity(points: np.ndarray, groups: np.ndarray, options: WindOptions, seed: int,
                  n_samples: int) -> np.ndarray:
    """Wind vectors (P, n_samples, 3) at `points` (P, 3) over one period (the clip's grid, end
    key excluded). `groups` (P,) labels points sharing one per-branch incoherent component.

    mean U along the direction + coherent gusts (von Kármán u and v, v smaller) + canopy
    turbulence (u, v, w), both frozen fields advected with the mean wind (delay x·dir/U, wrapped
    to the period because only harmonics of 1/duration are used) + per-branch incoherent noise.
    """
    o = options
    rng = np.random.default_rng(seed)
    field_rng = np.random.default_rng(o.field_seed) if o.field_seed is not None else rng
    phi = np.deg2rad(o.direction_deg)
    e_dir = np.array([np.cos(phi), np.sin(phi), 0.0])
    e_lat = np.array([-np.sin(phi), np.cos(phi), 0.0])
    e_up = np.array([0.0, 0.0, 1.0])
    u = o.speed
    n_bins = n_samples // 2 + 1
    n_max = min(n_bins - 2, int(np.floor(o.duration * o.fps / 4.0)))  # ≤ fps/4: little aliasing of |v|v
    p = np.asarray(points, dtype=np.float64) + np.asarray(o.origin, dtype=np.float64)
    u_adv = max(u, 1e-3)
    delay = (p @ e_dir) / u_adv

    out = np.broadcast_to(u * e_dir, (p.shape[0], n_samples, 3)).copy()
    if u == 0.0:
        return out
    along = np.zeros((p.shape[0], n_samples))       # Gaussian along-wind fluctuation, reshaped below

    def draw(r: np.random.Generator, rows: int) -> np.ndarray:
        return r.uniform(0.0, 2.0 * np.pi, size=(rows, n_bins))

    coherent = [  # (σ, length, lateral spectrum, axis; None = along-wind)
        (o.gust * u, o.gust_length, False, None),
        (LATERAL_RATIO * o.gust * u, o.gust_length, True, e_lat),
        (np.sqrt(1.0 - o.incoherent) * o.turbulence * u, o.turbulence_length, False, None),
        (np.sqrt(1.0 - o.incoherent) * LATERAL_RATIO * o.turbulence * u, o.turbulence_length, True, e_lat),
        (np.sqrt(1.0 - o.incoherent) * VERTICAL_RATIO * o.turbulence * u, o.turbulence_length, True, e_up),
    ]
    for sigma, length, lateral, axis in coherent:
        phase = draw(field_rng, 1)
        amp = _amplitudes(n_bins, n_max, o.duration, sigma, length, u_adv, lateral)
        series = _series(amp, phase, delay, o.duration, n_samples)
        if axis is None:
            along += series
        else:
            out += series[:, :, None] * axis

    uniq, inverse = np.unique(np.asarray(groups), return_inverse=True)
    group_delay = np.zeros(uniq.shape[0])
    incoherent = [
        (np.sqrt(o.incoherent) * o.turbulence * u, False, None),
        (np.sqrt(o.incoherent) * LATERAL_RATIO * o.turbulence * u, True, e_lat),
        (np.sqrt(o.incoherent) * VERTICAL_RATIO * o.turbulence * u, True, e_up),
    ]
    for sigma, lateral, axis in incoherent:
        phase = draw(rng, uniq.shape[0])
        amp = _amplitudes(n_bins, n_max, o.duration, sigma, o.turbulence_length, u_adv, lateral)
        series = _series(amp, phase, group_delay, o.duration, n_samples)[inverse]
        if axis is None:
            along += series
        else:
            out += series[:, :, None] * axis
    out += (_positive_gusts(along, u, np.hypot(o.gust, o.turbulence)) - u)[:, :, None] * e_dir
    return out


def _positive_gusts(fluctuation: np.ndarray, speed: float, intensity: float) -> np.ndarray:
    """Along-wind speed (P, n) from a Gaussian fluctuation of σ = intensity·speed: log-normal,
    U·exp(σ_ln·X − σ_ln²/2) with σ_ln² = ln(1 + intensity²), rescaled to mean U per point.

    Why: gust speeds are skewed and never reverse the mean wind; a Gaussian with a large gust
    knob blew trees upwind. Same mean and (nearly) the same σ as the Gaussian, always > 0."""
    if intensity <= 0.0:
        return np.full_like(fluctuation, speed)
    sigma_ln = np.sqrt(np.log1p(intensity * intensity))
    x = fluctuation / (intensity * speed)
    e = np.exp(sigma_ln * x)
    return speed * e / e.mean(axis=1, keepdims=True)


# ---------------------------------------------------------------------------------------------
# the bake

def _frames(options: WindOptions) -> tuple[int, np.ndarray]:
    times = loop_times(options.duration, options.fps)
    return len(times) - 1, times


def drag_pressure(v: np.ndarray, options: WindOptions) -> np.ndarray:
    """Drag per unit drag area (N/m²), vector along v: ½ρ|v|v, softened by Vogel's
    reconfiguration (1 + (|v|/U_r)²)^(B/2) so leaves streamline in strong wind (∝ |v|^(2+B))."""
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    soften = (1.0 + (speed / options.reconfig_speed) ** 2) ** (0.5 * options.vogel_exponent)
    return (0.5 * AIR_DENSITY) * soften * speed * v


def generalized_forces(tree: Tree, rig: Rig, options: WindOptions, seed: int, n: int,
                       loads: JointLoads) -> np.ndarray:
    """Torques (J, n, 3) about each joint of the wind on its whole subtree (the paper's load
    summed over the branch and its children), one period on the clip's grid."""
    v = wind_velocity(loads.pivot, rig.joint_stem, options, seed, n)          # (J, n, 3)
    pressure = drag_pressure(v, options)
    force = loads.area[:, None, None] * pressure                             # (J, n, 3)
    torque = np.cross(loads.area_moment[:, None, :], pressure)               # about own pivot
    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    for idx in reversed(depth_levels(parent)[1:]):
        p = parent[idx]
        d = loads.pivot[idx] - loads.pivot[p]
        np.add.at(torque, p, torque[idx] + np.cross(d[:, None, :], force[idx]))
        np.add.at(force, p, force[idx])
    return torque


def steady_state(dyn: Dynamics, torque: np.ndarray, duration: float) -> np.ndarray:
    """Periodic steady-state angles (J, n, 3) under periodic torques (J, n, 3), exactly: per rFFT
    harmonic ω and mode m, q̂ = φ_mᵀQ̂ / (ω_m² − ω² + 2iζω_mω); θ = Σ φ_m q_m. No spin-up, no
    transient: the result loops with continuous derivatives."""
    n_j, n = torque.shape[:2]
    Q = np.einsum("jca,jkc->jak", dyn.basis, torque).reshape(2 * n_j, n)     # (2J, n)
    spectrum = np.fft.rfft(Q, axis=1)
    omega = 2.0 * np.pi * np.arange(spectrum.shape[1]) / duration
    wm = dyn.omega[:, None]
    h = 1.0 / (wm * wm - omega[None, :] ** 2 + 2j * dyn.damping[:, None] * wm * omega[None, :])
    q = (dyn.modes.T @ spectrum) * h
    theta = np.fft.irfft(dyn.modes @ q, n=n, axis=1).reshape(n_j, 2, n)
    return np.einsum("jca,jak->jkc", dyn.basis, theta)


def bound_bends(theta: np.ndarray, parent: np.ndarray, options: WindOptions) -> np.ndarray:
    """Soft bounds, first on each joint frame's world-space turn Θ_j = Σ_{ancestors} θ (so a
    chain streams downwind instead of folding over however many joints it has), then on each
    joint's own turn: x → b·tanh(|x|/b)·x/|x|, smooth and identity for small angles."""
    def soft(x: np.ndarray, bound: float) -> np.ndarray:
        mag = np.linalg.norm(x, axis=-1, keepdims=True)
        safe = np.where(mag > 0.0, mag, 1.0)
        return np.where(mag > 0.0, bound * np.tanh(mag / bound) / safe, 0.0) * x

    levels = depth_levels(parent)
    total = theta.copy()
    for idx in levels[1:]:
        total[idx] += total[parent[idx]]
    total = soft(total, np.deg2rad(options.max_bend_deg))
    out = total.copy()
    for idx in levels[1:]:
        out[idx] -= total[parent[idx]]
    return soft(out, np.deg2rad(options.max_angle_deg))


# BLAS/LAPACK libraries found once, at import (before any worker thread of ours runs): a scan
# walks the loaded libraries under the dynamic loader's lock and would deadlock against a
# thread importing an extension
_BLAS = ThreadpoolController()


def one_blas_thread(fn):
    """Run `fn` with single-threaded BLAS/LAPACK: a threaded reduction sums in another order,
    so the same tree would bake to different bytes under `treegen make` (all cores) and a Dask
    worker; at these sizes (J <= 256) one thread is also faster."""
    @functools.wraps(fn)
    def run(*args, **kwargs):
        with _BLAS.limit(limits=1, user_api="blas"):
            return fn(*args, **kwargs)
    return run


@one_blas_thread
def wind_angles(tree: Tree, rig: Rig, options: WindOptions = DEFAULTS, seed: int = 0,
                dyn: Dynamics | None = None) -> np.ndarray:
    """World-frame rotation vectors (J, n, 3) of each joint's deviation from rest over one
    period (n = fps·duration samples, the closing key not repeated)."""
    n, _ = _frames(options)
    n_j = rig.skeleton.parent.shape[0]
    if options.speed == 0.0:
        return np.zeros((n_j, n, 3))
    loads = joint_loads(tree, rig, options)
    dyn = dyn if dyn is not None else dynamics(tree, rig, options, loads)
    torque = generalized_forces(tree, rig, options, seed, n, loads)
    theta = steady_state(dyn, torque, options.duration)
    return bound_bends(theta, np.asarray(rig.skeleton.parent, dtype=np.int64), options)


def bake_wind(tree: Tree, rig: Rig, options: WindOptions = DEFAULTS, seed: int = 0) -> Clip:
    """The wind clip: local rotation q_rest ∘ Δ per joint and key, Δ the wind deviation turned
    from world into the joint's rest frame (Δ_local = R_restᵀ θ_world), so the parent's motion
    carries through the hierarchy. Times 0..duration inclusive; last key == first key."""
    skel = rig.skeleton
    n, times = _frames(options)
    theta = wind_angles(tree, rig, options, seed)                             # (J, n, 3)
    n_j = theta.shape[0]
    rest = np.asarray(skel.rest_rotation, dtype=np.float64)
    rot = np.broadcast_to(rest[None], (n + 1, n_j, 4)).copy()
    moving = np.any(theta != 0.0, axis=(1, 2))
    if np.any(moving):
        idx = np.flatnonzero(moving)
        world_rest = Rotation.from_matrix(np.asarray(skel.bind_world)[idx, :3, :3]).as_matrix()
        local = np.einsum("jba,jkb->jka", world_rest, theta[idx])            # R_wᵀ θ
        half = 0.5 * np.linalg.norm(local, axis=2, keepdims=True)
        sinc = np.sinc(half / np.pi) * 0.5                                    # sin(h)/(2h)
        delta = np.concatenate([local * sinc, np.cos(half)], axis=2)          # (m, n, 4) xyzw
        q_rest = quat_unit(rest[idx])
        q = quat_mul(q_rest[:, None, :], delta)
        # keep the rest quaternion's hemisphere so LINEAR (slerp) keys never flip
        flip = np.einsum("jkc,jc->jk", q, rest[idx]) < 0.0
        q[flip] *= -1.0
        rot[:n, idx] = q.transpose(1, 0, 2)
        rot[n] = rot[0]
    return Clip(name="wind", times=times, rotations=rot, interpolation="LINEAR")


# ---------------------------------------------------------------------------------------------
# what an artist tunes with

@one_blas_thread
def wind_report(tree: Tree, rig: Rig, options: WindOptions = DEFAULTS, seed: int = 0,
                modes: int = 4) -> dict:
    """`treegen info --wind`: natural frequencies (Hz) and damping of the lowest modes and of
    the trunk's sway mode, and what the clip does at `options.speed`: the tree top's mean
    downwind lean and RMS sway (m), the largest joint turn (degrees)."""
    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    loads = joint_loads(tree, rig, options)
    dyn = dynamics(tree, rig, options, loads)
    sway = trunk_mode(tree, rig, options, loads, dyn)
    out = {
        "modes": [{"hz": round(float(w / (2 * np.pi)), 4), "damping": round(float(z), 4)}
                  for w, z in zip(dyn.omega[:modes], dyn.damping[:modes])],
        "sway_hz": round(float(dyn.omega[sway] / (2 * np.pi)), 4),
        "sway_damping": round(float(dyn.damping[sway]), 4),
        "speed_m_s": options.speed,
    }
    theta = wind_angles(tree, rig, options, seed, dyn)                 # (J, n, 3)
    j, x = trunk_top(tree, rig)
    phi = np.deg2rad(options.direction_deg)
    e_dir = np.array([np.cos(phi), np.sin(phi), 0.0])
    D = displacement_map(dyn, loads, parent, j, x)
    top = np.einsum("ia,ak->ki", D, np.einsum("jca,jkc->jak", dyn.basis, theta).reshape(D.shape[1], -1))
    along = top @ e_dir
    out |= {"top_lean_m": round(float(along.mean()), 4),
            "top_sway_rms_m": round(float(np.sqrt(np.mean(np.sum((top - top.mean(axis=0)) ** 2, axis=1)))), 4),
            "max_joint_deg": round(float(np.degrees(np.linalg.norm(theta, axis=2).max())), 2)}
    return out
