"""Wind: a seeded, periodic wind field and the paper's per-joint spring model, baked into a Clip.

Result: Tree + Rig → Clip "wind" with (fps·duration + 1, J, 4) local quaternions (xyzw);
key 0 == key K−1 (seamless loop), joint 0 (trunk base) always at rest, speed 0 → rest exactly.

    clip = bake_wind(tree, rig, WindOptions(speed=6.0, direction_deg=90), seed=7)

The model (Kondo et al., after Weber–Penn; REFERENCE.md §1, §3):

* Every joint carries the stem segments from its node up to the next joint on its chain, the
  leaves bound to it (``rig.leaf_joint``) and the stems it carries rigidly. The wind force on a
  joint's load is the leaves' drag F = ½·ρ_air·C_d·A·|v|·v (the paper's F_w = W·A with W the
  dynamic pressure, so it scales physically with speed; softened at high speed by Vogel's
  reconfiguration exponent), plus cylinder drag on the wood so leafless species still sway. Forces and their torques Σ (x_i − p_j) × F_i are summed over
  each joint's whole subtree with reverse (deepest-first) accumulation by depth.
* Gravity is in the rest shape already: its moment is constant and drops out of the deviation,
  so weight (F_g = G·(l·r²·π·d + A·A_g)) only enters as inertia.
* Each joint is a damped rotational spring: k = E·I/ℓ with I = π r⁴/4 (beam theory: curvature
  M/EI integrated over the span ℓ the joint bends over), floored so that the subtree's weight
  moment would sag it at most max_sag (Weber–Penn twigs are often thinner than wood could bear),
  inertia = second moment of the subtree mass about the joint, c = 2ζ√(k·I_m). It turns about the torque's component perpendicular to
  the branch (no twist), in the joint's rest world frame, composed down the hierarchy.
* Periodic steady state, exactly: the wind uses only harmonics of 1/duration, so the torque is
  periodic on the clip's grid; the system is linear, so each harmonic's response is the torque's
  rFFT coefficient divided by (k − I_m ω² + i c ω). The inverse rFFT is the motion after all
  transients have died out — it loops with continuous derivatives and needs no spin-up period.
  Angles then saturate smoothly (max_angle·tanh(θ/max_angle)) so gales never explode.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .asset import Clip
from .clip import loop_times
from .errors import TreegenError
from .quat import mul as quat_mul, unit as quat_unit
from .rig import Rig
from .skeleton import depth_levels
from .tree import Tree

AIR_DENSITY = 1.2          # kg/m³ at sea level, 20 °C
GRAVITY = 9.81             # m/s²
LATERAL_RATIO = 0.75       # σ_v / σ_u (lateral vs longitudinal gust; ESDU / ASCE ~0.75–0.88)
VERTICAL_RATIO = 0.5       # σ_w / σ_u


@dataclass(frozen=True)
class WindOptions:
    """Wind and wood parameters. Defaults: a pleasant 4 m/s breeze looping every 4 s."""

    speed: float = 4.0               # mean wind speed, m/s (Beaufort 3: 3.4–5.4)
    direction_deg: float = 0.0       # wind blows towards this azimuth; 0 = +X, 90 = +Y (Z up)
    gust: float = 0.35               # σ of the coherent gust process / mean speed
    turbulence: float = 0.3          # σ of the spatially varying part / mean speed
    duration: float = 4.0            # clip length = wind period, s
    fps: float = 30.0                # keys per second
    wood_density: float = 800.0      # kg/m³, green (living) wood is ~800; dry ~500–700
    leaf_areal_density: float = 0.2  # kg/m², fresh leaf mass per area (dry LMA ~0.05–0.1, ~60% water)
    drag_coefficient: float = 0.15   # C_d per one-sided leaf area at low speed; crown sheltering
                                     # included (whole crowns: ~0.5 of frontal ≈ 0.1–0.2 of leaf area)
    vogel_exponent: float = -0.5     # B: leaves streamline, drag ∝ |v|^(2+B) above reconfig_speed
    reconfig_speed: float = 2.0      # m/s, where reconfiguration sets in
    stem_drag_coefficient: float = 1.2  # cylinder C_d on the wood's 2·r·l; 0 = the paper's leaves only
    elastic_modulus: float = 9.0e9   # Pa, green wood E ≈ 8–10 GPa
    damping_ratio: float = 0.1       # ζ, structural + aerodynamic damping of branches
    max_angle_deg: float = 25.0      # soft bound on any joint's deviation from rest
    max_sag_deg: float = 5.0         # stiffness floor: its own weight bends no joint further
    gust_length: float = 30.0        # m, integral length scale of the gusts (von Kármán)
    turbulence_length: float = 3.0   # m, integral length scale of the canopy turbulence
    incoherent: float = 0.3          # share of the turbulence variance that is per-branch noise
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)  # tree position in the shared field, m
    field_seed: int | None = None    # seed of the shared (advected) field; None: the tree's seed

    def __post_init__(self) -> None:
        for name, (lo, hi, unit) in _RANGES.items():
            value = getattr(self, name)
            if not (np.isfinite(value) and lo <= value <= hi):
                raise TreegenError(
                    f"wind option '{name}' = {value!r}: allowed range {lo:g}..{hi:g} {unit}".rstrip()
                )
        for name in ("duration", "fps", "elastic_modulus", "max_angle_deg", "max_sag_deg", "gust_length",
                     "turbulence_length"):
            if getattr(self, name) <= 0:
                raise TreegenError(f"wind option '{name}' must be > 0, got {getattr(self, name)!r}")
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
    "damping_ratio": (0.001, 10.0, ""),
    "max_angle_deg": (0.0, 90.0, "degrees"),
    "max_sag_deg": (0.0, 90.0, "degrees"),
    "gust_length": (0.0, 1000.0, "m"),
    "turbulence_length": (0.0, 1000.0, "m"),
    "incoherent": (0.0, 1.0, ""),
}

DEFAULTS = WindOptions()


# ---------------------------------------------------------------------------------------------
# loads per joint

@dataclass(frozen=True, eq=False)
class JointLoads:
    """Static per-joint quantities of the spring model (subtree sums about each joint)."""

    pivot: np.ndarray        # (J, 3) joint positions at rest
    direction: np.ndarray    # (J, 3) unit branch direction at the joint
    area: np.ndarray         # (J,) drag area Σ C_d·A of the joint's own load, m²
    area_moment: np.ndarray  # (J, 3) Σ C_d·A_i (x_i − pivot) of its own load
    mass: np.ndarray         # (J,) subtree mass, kg
    inertia: np.ndarray      # (J,) subtree second moment of mass about the joint, kg·m²
    stiffness: np.ndarray    # (J,) k = max(E·π r⁴/4 / ℓ, |weight moment⊥| / max_sag), N·m/rad
    span: np.ndarray         # (J,) ℓ, m


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


def joint_loads(tree: Tree, rig: Rig, options: WindOptions = DEFAULTS) -> JointLoads:
    """Drag areas, masses, inertias and stiffnesses per joint (all vectorised)."""
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
    rod = np.concatenate([wood_mass * length**2 / 12.0, np.zeros_like(leaf_mass)])
    area = np.concatenate([wood_area, leaf_drag])
    rel = x - pivot[owner]

    own_area = np.bincount(owner, weights=area, minlength=n_j)
    own_moment = np.stack([np.bincount(owner, weights=area * rel[:, i], minlength=n_j)
                           for i in range(3)], axis=1)
    m_sub = np.bincount(owner, weights=mass, minlength=n_j)
    s_sub = np.stack([np.bincount(owner, weights=mass * rel[:, i], minlength=n_j)
                      for i in range(3)], axis=1)
    i_sub = np.bincount(owner, weights=mass * np.einsum("ij,ij->i", rel, rel) + rod, minlength=n_j)

    parent = np.asarray(skel.parent, dtype=np.int64)
    for idx in reversed(depth_levels(parent)[1:]):      # deepest first: parallel-axis accumulation
        p = parent[idx]
        d = pivot[idx] - pivot[p]
        np.add.at(i_sub, p, i_sub[idx] + 2.0 * np.einsum("ij,ij->i", s_sub[idx], d)
                  + m_sub[idx] * np.einsum("ij,ij->i", d, d))
        np.add.at(s_sub, p, s_sub[idx] + m_sub[idx, None] * d)
        np.add.at(m_sub, p, m_sub[idx])

    span = _joint_span(tree, rig)
    r = tree.node_radius[rig.joint_node]
    stiffness = options.elastic_modulus * np.pi * r**4 / 4.0 / span
    # Weber–Penn radii can be far thinner than wood could hold (a 1 mm, 1.5 m leafy branch):
    # the rest shape carries its weight, so a joint is at least stiff enough that its subtree's
    # weight, held out sideways, would bend it no more than max_sag (orientation-independent).
    weight_moment = GRAVITY * np.linalg.norm(s_sub, axis=1)
    stiffness = np.maximum(np.maximum(stiffness, weight_moment / np.deg2rad(options.max_sag_deg)),
                           1e-6)     # a massless zero-radius tip joint must not divide by zero
    return JointLoads(pivot, direction, own_area, own_moment, m_sub, i_sub, stiffness, span)


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
    """Cosine amplitudes of harmonics 0..n_bins−1 (only 1..n_max nonzero) with the spectrum's
    shape and total variance σ² over the clip's resolvable band (periodic: no energy lost)."""
    amp = np.zeros(n_bins)
    if n_max < 1 or sigma <= 0.0:
        return amp
    f = np.arange(1, n_max + 1) / duration
    s = _von_karman(f, length, speed, lateral)
    amp[1:n_max + 1] = np.sqrt(2.0 * s / s.sum()) * sigma     # Σ a²/2 = σ²
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

    def draw(r: np.random.Generator, rows: int) -> np.ndarray:
        return r.uniform(0.0, 2.0 * np.pi, size=(rows, n_bins))

    coherent = [  # (σ, length, lateral spectrum, axis)
        (o.gust * u, o.gust_length, False, e_dir),
        (LATERAL_RATIO * o.gust * u, o.gust_length, True, e_lat),
        (np.sqrt(1.0 - o.incoherent) * o.turbulence * u, o.turbulence_length, False, e_dir),
        (np.sqrt(1.0 - o.incoherent) * LATERAL_RATIO * o.turbulence * u, o.turbulence_length, True, e_lat),
        (np.sqrt(1.0 - o.incoherent) * VERTICAL_RATIO * o.turbulence * u, o.turbulence_length, True, e_up),
    ]
    for sigma, length, lateral, axis in coherent:
        phase = draw(field_rng, 1)
        amp = _amplitudes(n_bins, n_max, o.duration, sigma, length, u_adv, lateral)
        out += _series(amp, phase, delay, o.duration, n_samples)[:, :, None] * axis

    uniq, inverse = np.unique(np.asarray(groups), return_inverse=True)
    group_delay = np.zeros(uniq.shape[0])
    incoherent = [
        (np.sqrt(o.incoherent) * o.turbulence * u, False, e_dir),
        (np.sqrt(o.incoherent) * LATERAL_RATIO * o.turbulence * u, True, e_lat),
        (np.sqrt(o.incoherent) * VERTICAL_RATIO * o.turbulence * u, True, e_up),
    ]
    for sigma, lateral, axis in incoherent:
        phase = draw(rng, uniq.shape[0])
        amp = _amplitudes(n_bins, n_max, o.duration, sigma, o.turbulence_length, u_adv, lateral)
        out += _series(amp, phase, group_delay, o.duration, n_samples)[inverse][:, :, None] * axis
    return out


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


def wind_angles(tree: Tree, rig: Rig, options: WindOptions = DEFAULTS, seed: int = 0) -> np.ndarray:
    """World-frame rotation vectors (J, n, 3) of each joint's deviation from rest over one
    period (n = fps·duration samples, the closing key not repeated); root row is zero."""
    n, _ = _frames(options)
    n_j = rig.skeleton.parent.shape[0]
    if options.speed == 0.0 or n_j < 2:
        return np.zeros((n_j, n, 3))
    ld = joint_loads(tree, rig, options)
    v = wind_velocity(ld.pivot, rig.joint_stem, options, seed, n)           # (J, n, 3)
    pressure = drag_pressure(v, options)
    force = ld.area[:, None, None] * pressure                               # (J, n, 3)
    torque = np.cross(ld.area_moment[:, None, :], pressure)                 # about own pivot

    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    for idx in reversed(depth_levels(parent)[1:]):
        p = parent[idx]
        d = ld.pivot[idx] - ld.pivot[p]
        np.add.at(torque, p, torque[idx] + np.cross(d[:, None, :], force[idx]))
        np.add.at(force, p, force[idx])

    torque -= np.einsum("jkc,jc->jk", torque, ld.direction)[:, :, None] * ld.direction[:, None, :]
    spectrum = np.fft.rfft(torque, axis=1)                                   # (J, B, 3)
    omega = 2.0 * np.pi * np.arange(spectrum.shape[1]) / options.duration
    damping = 2.0 * options.damping_ratio * np.sqrt(ld.stiffness * ld.inertia)
    response = 1.0 / (ld.stiffness[:, None] - ld.inertia[:, None] * omega[None, :] ** 2
                      + 1j * damping[:, None] * omega[None, :])
    theta = np.fft.irfft(spectrum * response[:, :, None], n=n, axis=1)

    max_angle = np.deg2rad(options.max_angle_deg)
    mag = np.linalg.norm(theta, axis=2, keepdims=True)
    scale = np.where(mag > 0.0, max_angle * np.tanh(mag / max_angle) / np.where(mag > 0.0, mag, 1.0), 0.0)
    theta *= scale
    theta[parent < 0] = 0.0
    return theta


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
