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
* Weeping stems are as compliant as their drawn sag. A level the species draws hanging under
  its weight (its Curve and CurveBack bend it down by more than its random CurveV, or
  AttractionUp < 0 droops it) has the shape its weight bends it to: κ = M/EI ⇒ EI_eff = M/κ,
  the drawn turn of each joint's span toward its weight's moment where the stem still rises
  (below the horizontal the weight pulls along a hanging stem, so the curve there is growth),
  bounded above by E·π r⁴/4 so stems that do not sag keep the radius law, and below by twice
  the toppling moment of weight standing above the joint (a buckling safety factor of 2). Why: Weber–Penn draws the willow's limbs
  30 cm thick (Ratio 0.03, RatioPower 2); wood that thick would sag a small fraction of the
  drawn 120° arc and barely move in a breeze, while young, pendulous wood is far more compliant
  than a solid rod of that radius. Upturned and S-curved species (aspen, tupelo, oak) and every
  trunk keep the wood's stiffness.
* Periodic steady state, exactly: the wind uses only harmonics of 1/duration, so the loads are
  periodic on the clip's grid; each harmonic's modal response is φᵀQ̂ / (ω_m² − ω² + 2iζ_mω_mω).
  The inverse rFFT is the motion after all transients have died out — it loops with continuous
  derivatives and needs no spin-up period.
* Gusts are log-normal along the wind (never reversing it). Large motion is bounded softly
  (b·tanh(|x|/b)): first each joint frame's world-space turn summed down its chain (so chains
  stream downwind instead of folding over), then each joint's own turn.

Modules: wind_options (the options), wind_loads (loads and springs per joint), wind_dynamics
(the linear system and its modes), wind_field (the field and its torques); this one solves,
bounds and bakes, and reports what an artist tunes with.
"""

from __future__ import annotations

import functools
import threading
from dataclasses import replace

import numpy as np
from threadpoolctl import ThreadpoolController

from .asset import Clip
from .clip import loop_times
from .quat import mul as quat_mul, unit as quat_unit
from .rig import Rig
from .skeleton import depth_levels
from .tree import Tree
from .wind_dynamics import Dynamics, displacement_map, dynamics, trunk_top
from .wind_field import drag_pressure, generalized_forces, wind_velocity
from .wind_loads import JointLoads, joint_loads
from .wind_options import AIR_DENSITY, DEFAULTS, GRAVITY, WindOptions

__all__ = [
    "AIR_DENSITY",
    "DEFAULTS",
    "GRAVITY",
    "Dynamics",
    "JointLoads",
    "WindOptions",
    "bake_wind",
    "bound_bends",
    "drag_pressure",
    "dynamics",
    "generalized_forces",
    "joint_loads",
    "one_blas_thread",
    "steady_state",
    "sway",
    "wind_angles",
    "wind_report",
    "wind_velocity",
]


# ---------------------------------------------------------------------------------------------
# the bake


def _frames(options: WindOptions) -> tuple[int, np.ndarray]:
    times = loop_times(options.duration, options.fps)
    return len(times) - 1, times


def in_axes(basis: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Components (J, a, n) of vectors v (J, n, 3) along each joint's axes basis (J, 3, a):
    np.einsum("jca,jkc->jak", basis, v) to the bit (see _summed), 10× faster on these shapes."""
    return _summed(basis[:, c, :, None] * v[:, None, :, c] for c in range(basis.shape[1]))


def from_axes(basis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Vectors (J, n, 3) of components q (J, a, n) along the axes basis (J, 3, a):
    np.einsum("jca,jak->jkc", basis, q) to the bit for the two bending axes used here (a = 2;
    with three einsum may pair the terms otherwise, see _summed)."""
    return _summed(basis[:, None, :, a] * q[:, a, :, None] for a in range(basis.shape[2]))


def _summed(terms) -> np.ndarray:
    """0.0 + t0 + t1 + …, left to right: einsum's sum of products in its own order, from zero
    as it starts (so −0.0 products sum to +0.0 alike), without its slow strided loop over
    many small per-joint products (checked bit for bit on five species' makes)."""
    out = 0.0
    for t in terms:
        out = out + t
    return out  # type: ignore[return-value]


def steady_state(dyn: Dynamics, torque: np.ndarray, duration: float) -> np.ndarray:
    """Periodic steady-state angles (J, n, 3) under periodic torques (J, n, 3), exactly: per rFFT
    harmonic ω and mode m, q̂ = φ_mᵀQ̂ / (ω_m² − ω² + 2iζω_mω); θ = Σ φ_m q_m. No spin-up, no
    transient: the result loops with continuous derivatives."""
    n_j, n = torque.shape[:2]
    Q = in_axes(dyn.basis, torque).reshape(2 * n_j, n)  # (2J, n)
    spectrum = np.fft.rfft(Q, axis=1)
    omega = 2.0 * np.pi * np.arange(spectrum.shape[1]) / duration
    wm = dyn.omega[:, None]
    h = 1.0 / (wm * wm - omega[None, :] ** 2 + 2j * dyn.damping[:, None] * wm * omega[None, :])
    q = (dyn.modes.T @ spectrum) * h
    theta = np.fft.irfft(dyn.modes @ q, n=n, axis=1).reshape(n_j, 2, n)
    return from_axes(dyn.basis, theta)


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


CROWN_SAMPLES = 200  # leaves whose mean is the crown's centre (crown_map)
SWAY_RUN = 120.0  # s of wind whose crown spectrum gives the sway frequency (1/120 Hz bins)
SWAY_FPS = 4.0  # its frames per second (sways are well under 2 Hz)

# BLAS/LAPACK libraries found once, at import (before any worker thread of ours runs): a scan
# walks the loaded libraries under the dynamic loader's lock and would deadlock against a
# thread importing an extension
_BLAS = ThreadpoolController()


_LIMIT_LOCK = threading.Lock()
_limit: dict = {"inside": 0, "limiter": None}  # calls inside one_blas_thread, and their limit


def one_blas_thread(fn):
    """Run `fn` with single-threaded BLAS/LAPACK: a threaded reduction sums in another order,
    so the same tree would bake to different bytes under `treegen make` (all cores) and a Dask
    worker; at these sizes (J <= 256) one thread is also faster. The limit is the process's:
    the first call in sets it and the last one out restores it, so builds overlapping in
    threads (the API, a multi-threaded Dask worker) all run inside it."""

    @functools.wraps(fn)
    def run(*args, **kwargs):
        with _LIMIT_LOCK:
            if _limit["inside"] == 0:
                _limit["limiter"] = _BLAS.limit(limits=1, user_api="blas")
            _limit["inside"] += 1
        try:
            return fn(*args, **kwargs)
        finally:
            with _LIMIT_LOCK:
                _limit["inside"] -= 1
                if _limit["inside"] == 0:
                    _limit["limiter"].restore_original_limits()

    return run


@one_blas_thread
def wind_angles(
    tree: Tree, rig: Rig, options: WindOptions = DEFAULTS, seed: int = 0, dyn: Dynamics | None = None
) -> np.ndarray:
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


def bake_wind(
    tree: Tree, rig: Rig, options: WindOptions = DEFAULTS, seed: int = 0, theta: np.ndarray | None = None
) -> Clip:
    """The wind clip: local rotation q_rest ∘ Δ per joint and key, Δ the wind deviation turned
    from world into the joint's rest frame (Δ_local = R_restᵀ θ_world), so the parent's motion
    carries through the hierarchy. Times 0..duration inclusive; last key == first key.
    `theta`: the bends (J, n, 3) if already known (wind_angles, wind_lods.lod_angles)."""
    skel = rig.skeleton
    n, times = _frames(options)
    if theta is None:
        theta = wind_angles(tree, rig, options, seed)  # (J, n, 3)
    n_j = theta.shape[0]
    rest = np.asarray(skel.rest_rotation, dtype=np.float64)
    rot = np.broadcast_to(rest[None], (n + 1, n_j, 4)).copy()
    moving = np.any(theta != 0.0, axis=(1, 2))
    if np.any(moving):
        from scipy.spatial.transform import Rotation  # (0.2 s to import: only where used)

        idx = np.flatnonzero(moving)
        world_rest = Rotation.from_matrix(np.asarray(skel.bind_world)[idx, :3, :3]).as_matrix()
        local = in_axes(world_rest, theta[idx]).transpose(0, 2, 1)  # R_wᵀ θ (m, n, 3)
        half = 0.5 * np.linalg.norm(local, axis=2, keepdims=True)
        sinc = np.sinc(half / np.pi) * 0.5  # sin(h)/(2h)
        delta = np.concatenate([local * sinc, np.cos(half)], axis=2)  # (m, n, 4) xyzw
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


def crown_map(tree: Tree, rig: Rig, dyn: Dynamics, loads: JointLoads) -> np.ndarray:
    """(3, 2J) small-angle motion of the crown's centre (the leaves' area-weighted mean, a
    sample of CROWN_SAMPLES; the trunk top for a leafless tree) per bending angle."""
    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    if not tree.n_leaves:
        j, x = trunk_top(tree, rig)
        return displacement_map(dyn, loads, parent, j, x)
    pick = np.arange(0, tree.n_leaves, max(1, tree.n_leaves // CROWN_SAMPLES))
    w = tree.leaf_area[pick] / tree.leaf_area[pick].sum()
    maps = [displacement_map(dyn, loads, parent, int(rig.leaf_joint[i]), tree.leaf_pos[i]) for i in pick]
    return np.tensordot(w, np.stack(maps), axes=1)


def sway(
    tree: Tree,
    rig: Rig,
    options: WindOptions,
    seed: int,
    dyn: Dynamics,
    loads: JointLoads,
    theta: np.ndarray | None = None,
):
    """(Hz, mode) of the tree's sway as one sees it: the peak of the crown centre's horizontal
    sway-velocity spectrum (smoothed over ±0.02 Hz) in a SWAY_RUN-long run of the same wind,
    and the mode carrying most of that motion within ±25 % of the peak. A single mode picked
    by the trunk top's static deflection was one heavy limb's pendulum on a fine rig (the
    willow's 0.11 Hz, while its crown sways at 0.2 Hz), and the mode with the most crown
    velocity alone jumped between close modes with the clip's length. `theta`: the clip's
    bends at `options`, reused when that clip is already the run."""
    run = replace(options, duration=max(options.duration, SWAY_RUN), fps=min(options.fps, SWAY_FPS))
    if theta is None or run != options:
        theta = wind_angles(tree, rig, run, seed, dyn)
    if not np.any(theta):
        return float(dyn.omega[0] / (2 * np.pi)) if len(dyn.omega) else 0.0, 0
    crown = crown_map(tree, rig, dyn, loads)
    dof = np.einsum("jca,jkc->jak", dyn.basis, theta).reshape(2 * theta.shape[0], -1)  # (2J, n)
    x = (crown[:2] @ dof).T  # (n, 2) horizontal crown motion
    v = np.diff(np.concatenate([x, x[:1]]), axis=0)  # periodic
    power = (np.abs(np.fft.rfft(v, axis=0)) ** 2).sum(axis=1)
    f = np.fft.rfftfreq(len(v), 1.0 / run.fps)
    k = max(1, int(round(0.02 * run.duration)))
    smooth = np.convolve(power, np.ones(2 * k + 1) / (2 * k + 1), mode="same")
    band = f > 0.05
    peak = float(f[band][np.argmax(smooth[band])])
    q = dyn.modes.T @ (dyn.mass @ dof)  # modal coordinates (φᵀ M φ = I)
    share = ((crown[:2] @ dyn.modes) ** 2).sum(axis=0) * np.diff(q, axis=1, append=q[:, :1]).var(axis=1)
    hz = dyn.omega / (2 * np.pi)
    near = np.abs(hz - peak) <= 0.25 * peak
    mode = int(np.argmax(np.where(near, share, -np.inf))) if near.any() else int(np.argmin(np.abs(hz - peak)))
    return peak, mode


@one_blas_thread
def wind_report(tree: Tree, rig: Rig, options: WindOptions = DEFAULTS, seed: int = 0, modes: int = 4) -> dict:
    """`treegen info --wind`: natural frequencies (Hz) and damping of the lowest modes and of
    the tree's sway (sway: its crown's spectrum peak and that mode's damping), and what the clip does at `options.speed`: the tree top's mean
    downwind lean and RMS sway (m), the largest joint turn (degrees)."""
    parent = np.asarray(rig.skeleton.parent, dtype=np.int64)
    loads = joint_loads(tree, rig, options)
    dyn = dynamics(tree, rig, options, loads)
    theta = wind_angles(tree, rig, options, seed, dyn)  # (J, n, 3)
    sway_hz, mode = sway(tree, rig, options, seed, dyn, loads, theta)
    out = {
        "modes": [
            {"hz": round(float(w / (2 * np.pi)), 4), "damping": round(float(z), 4)}
            for w, z in zip(dyn.omega[:modes], dyn.damping[:modes])
        ],
        "sway_hz": round(sway_hz, 4),
        "sway_damping": round(float(dyn.damping[mode]), 4),
        "speed_m_s": options.speed,
    }
    j, x = trunk_top(tree, rig)
    phi = np.deg2rad(options.direction_deg)
    e_dir = np.array([np.cos(phi), np.sin(phi), 0.0])
    D = displacement_map(dyn, loads, parent, j, x)
    top = np.einsum("ia,ak->ki", D, np.einsum("jca,jkc->jak", dyn.basis, theta).reshape(D.shape[1], -1))
    along = top @ e_dir
    out |= {
        "top_lean_m": round(float(along.mean()), 4),
        "top_sway_rms_m": round(float(np.sqrt(np.mean(np.sum((top - top.mean(axis=0)) ** 2, axis=1)))), 4),
        "max_joint_deg": round(float(np.degrees(np.linalg.norm(theta, axis=2).max())), 2),
    }
    return out
