"""The wind field over one loop and the torques it puts on the joints.

A seeded, periodic field (only harmonics of 1/duration): mean wind, coherent von Kármán gusts
(log-normal along the wind, never reversing it), canopy turbulence advected with the mean wind,
and per-branch incoherent noise; its drag, summed over each joint's subtree (wind.py's model).
"""

from __future__ import annotations

import numpy as np

from .rig import Rig
from .skeleton import depth_levels
from .tree import Tree
from .wind_loads import JointLoads
from .wind_options import AIR_DENSITY, LATERAL_RATIO, VERTICAL_RATIO, WindOptions


def _von_karman(f: np.ndarray, length: float, speed: float, lateral: bool) -> np.ndarray:
    """Von Kármán one-sided spectrum shape (unit variance) at frequencies f (Hz)."""
    n = f * length / speed
    if not lateral:
        return 4.0 * (length / speed) / (1.0 + 70.8 * n * n) ** (5.0 / 6.0)
    return 4.0 * (length / speed) * (1.0 + 755.2 * n * n) / (1.0 + 283.2 * n * n) ** (11.0 / 6.0)


def _amplitudes(
    n_bins: int, n_max: int, duration: float, sigma: float, length: float, speed: float, lateral: bool
) -> np.ndarray:
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
    amp[1 : n_max + 1] = np.sqrt(2.0 * s / duration) * sigma
    return amp


def _series(amp: np.ndarray, phase: np.ndarray, delay: np.ndarray, duration: float, n: int) -> np.ndarray:
    """Real periodic signals (P, n) with cosine amplitudes `amp` (B,), phases (P|1, B) delayed by
    `delay` (P,) seconds: Σ a_b cos(2π f_b (t − delay) + φ_b), evaluated by inverse rFFT."""
    f = np.arange(amp.shape[0]) / duration
    coef = (0.5 * n) * amp[None, :] * np.exp(1j * (phase - 2.0 * np.pi * f[None, :] * delay[:, None]))
    return np.fft.irfft(coef, n=n, axis=1)


def wind_velocity(
    points: np.ndarray, groups: np.ndarray, options: WindOptions, seed: int, n_samples: int
) -> np.ndarray:
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
    along = np.zeros((p.shape[0], n_samples))  # Gaussian along-wind fluctuation, reshaped below

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


def drag_pressure(v: np.ndarray, options: WindOptions) -> np.ndarray:
    """Drag per unit drag area (N/m²), vector along v: ½ρ|v|v, softened by Vogel's
    reconfiguration (1 + (|v|/U_r)²)^(B/2) so leaves streamline in strong wind (∝ |v|^(2+B))."""
    speed = np.linalg.norm(v, axis=-1, keepdims=True)
    soften = (1.0 + (speed / options.reconfig_speed) ** 2) ** (0.5 * options.vogel_exponent)
    return (0.5 * AIR_DENSITY) * soften * speed * v


def generalized_forces(
    tree: Tree, rig: Rig, options: WindOptions, seed: int, n: int, loads: JointLoads
) -> np.ndarray:
    """Torques (J, n, 3) about each joint of the wind on its whole subtree (the paper's load
    summed over the branch and its children), one period on the clip's grid."""
    v = wind_velocity(loads.pivot, rig.joint_stem, options, seed, n)  # (J, n, 3)
    pressure = drag_pressure(v, options)
    force = loads.area[:, None, None] * pressure  # (J, n, 3)
    torque = np.cross(loads.area_moment[:, None, :], pressure)  # about own pivot
    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    for idx in reversed(depth_levels(parent)[1:]):
        p = parent[idx]
        d = loads.pivot[idx] - loads.pivot[p]
        np.add.at(torque, p, torque[idx] + np.cross(d[:, None, :], force[idx]))
        np.add.at(force, p, force[idx])
    return torque
