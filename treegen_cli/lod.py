"""LOD planning: when each LOD takes over, and the view maths every LOD stage shares.

**Switches.** By default a tree's LODs switch on its height on screen, as engines' LOD groups
do: LOD k+1 takes over when the tree's height falls below `screen[k]` of the screen height
(0.5 / 0.25 / 0.1), i.e. from distance height / (screen[k] · 2·tan(fov_y/2)) of the centre of
its bounds (`switch_distances`); `distances` forces metres instead.

**Pixels.** A pinhole camera (fov, width) anywhere at distance d from the centre of the tree's
bounds, looking at that centre, in any direction: with R the farthest any vertex gets from
that centre, a point is at depth ≥ d − R and at most atan(R/√(d² − R²)) off axis, so a
movement δ shows as at most f·δ·d / ((d − R)·√(d² − R²)) pixels, f = width/2 / tan(fov/2)
(`near_pixel_size`, the bound the decimation keeps).

The LOD stage's other parts: `lod_decimate.py` (the paper's leaf update schedule as keyframe
decimation, on `lod_probes.py`'s points and `lod_playback.py`'s engine-like playback),
`lod_budget.py` and `lod_leaves.py` (geometric LODs), `lod_report.py` (the paper's Table 3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .errors import OptionError, TreegenError

SCHEDULES = ("bounded", "bounded-step", "paper")
MIN_SCREEN = 1e-4  # a LOD switch at least this many screen heights tall (a tenth of a pixel
# on a 1080 px screen): --lod-screen 1e-300 put a LOD 10^300 m away
MAX_DISTANCE = 1e6  # metres, a switch distance at most (--lod-distances 0,1e308 crashed the
# cover estimator; a 100 m tree is under a pixel from 170 km on)
MAX_SCREEN = 4.0  # a LOD switch at most this many screen heights tall: beyond, the camera is
# inside the tree (--lod-screen 50,25,10, percentages typed for fractions, put LOD3 at 2.9 m)


@dataclass(frozen=True)
class LodOptions:
    """View and error model, and the per-LOD coarsening tables (index = LOD; last repeats).

    screen: tree height / screen height below which LOD1, LOD2, … take over (descending);
    distances: metres from the centre of the tree's bounds from which each LOD is used,
    ascending, LOD0 first (0 → its clip is dense); when given it replaces `screen`. fov_deg is
    horizontal, width in pixels, aspect = width/height (the vertical fov for `screen`)."""

    distances: tuple[float, ...] | None = None
    screen: tuple[float, ...] = (0.5, 0.25, 0.1)
    fov_deg: float = 60.0
    width: int = 1920
    error_px: float = 1.0
    schedule: str = "bounded"  # see lod_decimate.py
    aspect: float = 16.0 / 9.0
    sides: tuple[tuple[int, ...], ...] = ((16, 8, 6, 4, 3), (8, 6, 4, 3), (6, 4, 3), (4, 3))
    joint_fraction: tuple[float, ...] = (1.0, 0.5, 0.25, 0.125)  # × the joint budget
    triangles: tuple[float, ...] = (1.0, 0.5, 0.15, 0.05)  # × LOD0's triangles (lod_budget.py)
    max_iterations: int = 200  # playback-check refinement rounds per level

    def __post_init__(self) -> None:
        d = self.distances
        if d is not None:
            shown = ",".join(f"{x:g}" for x in d) or "(none)"
            if not d or any(not math.isfinite(x) or x < 0 for x in d) or list(d) != sorted(d):
                raise OptionError(
                    "distances",
                    shown,
                    "give one or more ascending distances in metres, each >= 0",
                    "--lod-distances",
                )
            if max(d) > MAX_DISTANCE:
                raise OptionError(
                    "distances",
                    shown,
                    f"each at most {MAX_DISTANCE:,.0f} m (any tree is under a pixel long before)",
                    "--lod-distances",
                )
            if len(set(d)) != len(d):
                raise OptionError("distances", shown, "distances repeat", "--lod-distances")
        s = self.screen
        if (
            (d is None and not s)
            or any(not (math.isfinite(x) and MIN_SCREEN <= x <= MAX_SCREEN) for x in s)
            or list(s) != sorted(s, reverse=True)
            or len(set(s)) != len(s)
        ):
            raise OptionError(
                "screen",
                ",".join(f"{x:g}" for x in s) or "(none)",
                f"give descending fractions of the screen height (not percentages), each in "
                f"[{MIN_SCREEN:g}, {MAX_SCREEN:g}], e.g. 0.5,0.25,0.1",
                "--lod-screen",
            )
        if not 0.0 < self.fov_deg < 180.0:
            raise OptionError(
                "fov_deg", self.fov_deg, "the horizontal field of view must be in (0, 180) degrees", "--fov"
            )
        if self.schedule == "paper" and self.fov_deg >= 90.0:
            raise OptionError(
                "fov_deg", self.fov_deg, "the paper's tan(fov) form needs fov < 90 degrees", "--fov"
            )
        if not 1 <= self.width <= 1_000_000:
            raise OptionError("width", self.width, "screen width must be in 1..1000000 pixels", "--width")
        if not (math.isfinite(self.error_px) and 0.0 <= self.error_px <= 1000.0):
            raise OptionError("error_px", self.error_px, "allowed range 0..1000 pixels", "--error-px")
        if self.schedule not in SCHEDULES:
            raise OptionError("schedule", self.schedule, f"use one of {', '.join(SCHEDULES)}", "--schedule")
        if not (self.aspect > 0 and self.max_iterations >= 1):
            raise TreegenError("LOD aspect must be > 0 and max_iterations >= 1")
        if (
            min(self.joint_fraction) <= 0
            or max(self.joint_fraction) > 1
            or min(min(s) for s in self.sides) < 3
        ):
            raise TreegenError("LOD tables: joint_fraction in (0, 1], sides >= 3")
        t = self.triangles
        if not t or any(not (math.isfinite(x) and 0.0 < x <= 1.0) for x in t):
            raise TreegenError(
                f"--lod-triangles {','.join(f'{x:g}' for x in t) or '(none)'}: "
                "give fractions of LOD0's triangles, each in (0, 1]"
            )

    @property
    def interpolation(self) -> str:
        """How the kept keys are played: slerp for "bounded", held for the others."""
        return "LINEAR" if self.schedule == "bounded" else "STEP"

    @property
    def count(self) -> int:
        """Number of LODs."""
        return len(self.distances) if self.distances is not None else len(self.screen) + 1


LOD_DEFAULTS = LodOptions()


def _tan_half_fov_y(options: LodOptions) -> float:
    return math.tan(0.5 * math.radians(options.fov_deg)) / options.aspect


def switch_distances(height: float, options: LodOptions = LOD_DEFAULTS) -> tuple[float, ...]:
    """Metres from which each LOD is used for a tree `height` metres tall: `distances` as
    given, else 0 and, per screen fraction s, the distance at which the tree's height fills s
    of the screen height: height / (s · 2·tan(fov_y/2)).

    Result (height 13 m, fov 60°, 16:9, screen 0.5/0.25/0.1): (0, 40.0, 80.1, 200.1) m."""
    if options.distances is not None:
        return tuple(float(x) for x in options.distances)
    return (0.0,) + tuple(screen_distance(height, s, options) for s in options.screen)


def screen_distance(
    height: float, share: float, options: LodOptions = LOD_DEFAULTS, of: float = 1.0
) -> float:
    """Metres from which a tree `height` metres tall fills `share` of `of` of the screen
    height: a fraction (of = 1, `--lod-screen`) or pixels (of = width / aspect, the
    impostor's switch_px). height · of / (share · 2·tan(fov_y/2))."""
    return float(height * of / (share * (2.0 * _tan_half_fov_y(options))))


def pixel_size(distance: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """Metres spanned by one pixel at the centre of the screen at `distance`: 2·d·tan(fov/2)/width."""
    return 2.0 * distance * math.tan(0.5 * math.radians(options.fov_deg)) / options.width


def paper_pixel_size(distance: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """The paper's threshold per unit i: P/d > i·tan(fov_x)/width, i.e. d·tan(fov)/width
    (1.5× the exact pixel at 60°)."""
    return distance * math.tan(math.radians(options.fov_deg)) / options.width


def near_pixel_size(distance: float, radius: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """Metres of movement that show as at most one pixel for every point within `radius` of a
    centre, seen by a pinhole camera at `distance` from that centre looking at it, from any
    direction (see the module doc): (d − R)·√(d² − R²) / (d·f). 0 when d ≤ R (the camera may be
    inside: no finite bound)."""
    d, r = float(distance), float(radius)
    if d <= r:
        return 0.0
    f = 0.5 * options.width / math.tan(0.5 * math.radians(options.fov_deg))
    return (d - r) * math.sqrt(d * d - r * r) / (d * f)


def screen_coverage(height: float, distance: float, options: LodOptions = LOD_DEFAULTS) -> float:
    """Screen height a tree of `height` metres fills at `distance`, as a fraction of the view
    (above 1 when it overflows the screen; not clamped, so glTF's MSFT_screencoverage switches
    LODs at the same distances as USD's distance heuristic)."""
    if distance <= 0:
        return 1.0
    return float(height / (2.0 * distance * _tan_half_fov_y(options)))
