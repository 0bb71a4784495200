"""Wind options: the wind and wood parameters of the bake, their defaults and allowed ranges.

Its own module so that the front door (api.py), the forest layout and the wind's own modules
share one set of defaults without importing the bake.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import OptionError, TreegenError

AIR_DENSITY = 1.2  # kg/m³ at sea level, 20 °C
GRAVITY = 9.81  # m/s²
LATERAL_RATIO = 0.75  # σ_v / σ_u (lateral vs longitudinal gust; ESDU / ASCE ~0.75–0.88)
VERTICAL_RATIO = 0.5  # σ_w / σ_u


@dataclass(frozen=True)
class WindOptions:
    """Wind and wood parameters. Defaults: a pleasant 4 m/s breeze looping every 10 s."""

    speed: float = 4.0  # mean wind speed, m/s (Beaufort 3: 3.4–5.4)
    direction_deg: float = 0.0  # wind blows towards this azimuth; 0 = +X, 90 = +Y (Z up)
    gust: float = 0.35  # σ of the coherent gust process / mean speed
    turbulence: float = 0.3  # σ of the spatially varying part / mean speed
    duration: float = 10.0  # clip length = wind period, s (long enough not to notice)
    fps: float = 30.0  # keys per second
    wood_density: float = 800.0  # kg/m³, green (living) wood is ~800; dry ~500–700
    leaf_areal_density: float = 0.2  # kg/m², fresh leaf mass per area (dry LMA ~0.05–0.1, ~60% water)
    drag_coefficient: float = 0.15  # C_d per one-sided leaf area at low speed; crown sheltering
    # included (whole crowns: ~0.5 of frontal ≈ 0.1–0.2 of leaf area)
    vogel_exponent: float = -0.5  # B: leaves streamline, drag ∝ |v|^(2+B) above reconfig_speed
    reconfig_speed: float = 2.0  # m/s, where reconfiguration sets in
    stem_drag_coefficient: float = 1.2  # cylinder C_d on the wood's 2·r·l; 0 = the paper's leaves only
    elastic_modulus: float = 6.0e9  # Pa, green wood (Wood Handbook: 5.4–7.1 GPa for the paper's
    # aspen, tupelo, willow and oak)
    anchorage: float = 1500.0  # N·m/rad per kg of tree: root-plate rotational stiffness
    # (winching tests: ~150 N·m/kg turning moment at ~0.1 rad)
    stiffness: float = 1.0  # multiplier on every spring (artist's knob: f ∝ √stiffness)
    working_stress: float = 10.0e6  # Pa, bending stress wood holds its own weight at (green
    # modulus of rupture ~40 MPa over a safety factor ~4)
    damping_ratio: float = 0.15  # structural ζ of every mode (drag adds aerodynamic ζ; trees in leaf
    # measure ~0.05–0.2)
    max_bend_deg: float = 60.0  # soft bound on any joint frame's world-space turn from rest
    max_angle_deg: float = 40.0  # soft bound on any joint's own deviation from rest
    gust_length: float = 80.0  # m, integral length scale of the gusts (von Kármán; ESDU 85020:
    # ~50–150 m at 10–30 m height in open country)
    turbulence_length: float = 3.0  # m, integral length scale of the canopy turbulence
    incoherent: float = 0.3  # share of the turbulence variance that is per-branch noise
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)  # tree position in the shared field, m
    field_seed: int | None = None  # seed of the shared (advected) field; None: the tree's seed

    def __post_init__(self) -> None:
        for name, (lo, hi, unit) in _RANGES.items():
            value = getattr(self, name)
            positive = name in _POSITIVE  # one range text whichever side a value misses
            allowed = (
                f"allowed range (0, {hi:g}] {unit}" if positive else f"allowed range {lo:g}..{hi:g} {unit}"
            )
            if not (np.isfinite(value) and lo <= value <= hi):
                raise OptionError(name, value, allowed.rstrip(), f"WindOptions.{name}")
            if positive and value <= 0:
                raise OptionError(name, value, f"must be > 0; {allowed}".rstrip(), f"WindOptions.{name}")
        if self.duration * self.fps < MIN_FRAMES:  # a loop of one key is a still pose; blamed on
            # the one farther below its default (--fps 0.1 is the slip, not the 10 s duration)
            if self.fps / 30.0 < self.duration / 10.0:
                least = f"at least {math.ceil(1000 * MIN_FRAMES / self.duration) / 1000:g} fps"
                name, value, other = "fps", self.fps, f"a {self.duration:g} s loop"
            else:
                least = f"at least {math.ceil(1000 * MIN_FRAMES / self.fps) / 1000:g} s"
                name, value, other = "duration", self.duration, f"{self.fps:g} fps"
            raise OptionError(
                name,
                value,
                f"under {MIN_FRAMES} frames with {other}, the loop would stand still; {least}",
                f"WindOptions.{name}",
            )
        if len(self.origin) != 3 or not np.all(np.isfinite(self.origin)):
            raise TreegenError(f"wind option 'origin' must be three finite numbers, got {self.origin!r}")


MIN_FRAMES = 2  # frames a loop needs to move (duration × fps): one frame is a still pose
_POSITIVE = (  # must be > 0, not only ≥ the range's 0
    "duration",
    "fps",
    "elastic_modulus",
    "stiffness",
    "working_stress",
    "anchorage",
    "max_angle_deg",
    "max_bend_deg",
    "gust_length",
    "turbulence_length",
)
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
