"""Wind on the vehicle: a steady mean wind and gusts, seeded (pure: no clock, no I/O).

The air moves at ``mean + gust(t)`` (NED, m/s). The mean blows horizontally from ``from_deg`` (degrees
clockwise from north, where the wind comes *from*, as weather reports give it; drawn from the seed when not
given). Each gust component is a first-order Gauss-Markov process (the first-order form of the Dryden
turbulence model): standard deviation ``gust_mps`` horizontally and half that vertically, correlation time
``tau_s``, updated every ``update_s`` of simulation time. The vehicle's linear drag acts on its velocity
relative to the air (:class:`sitl_vehicle.dynamics.QuadDynamics` ``wind``), so a hovering vehicle leans
into the wind and a free one drifts with it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class WindConfig:
    mean_mps: float = 0.0  # m/s, steady wind speed
    gust_mps: float = 0.0  # m/s, standard deviation of each horizontal gust component (vertical: half)
    from_deg: float | None = None  # deg, direction the wind comes from (None: drawn from the seed)
    tau_s: float = 2.0  # s, gust correlation time
    update_s: float = 0.02  # s, how often the gust process steps (50 Hz: gusts are far slower)

    def __post_init__(self) -> None:
        for name in ("mean_mps", "gust_mps"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"wind {name} must be a finite number >= 0 (got {value})")
        if self.from_deg is not None and not math.isfinite(self.from_deg):
            raise ValueError(f"wind from_deg must be finite (got {self.from_deg})")
        if not (self.tau_s > 0 and self.update_s > 0):
            raise ValueError("wind tau_s and update_s must be positive")

    @property
    def calm(self) -> bool:
        return self.mean_mps == 0 and self.gust_mps == 0


class WindModel:
    """``velocity(t)``: the air's NED velocity at simulation time ``t`` (non-decreasing across calls)."""

    def __init__(self, config: WindConfig, rng: np.random.Generator) -> None:
        self.config = config
        self._rng = rng
        from_deg = config.from_deg if config.from_deg is not None else float(rng.uniform(0.0, 360.0))
        self.from_deg = from_deg
        to = math.radians(from_deg) + math.pi     # the air moves away from where it comes from
        self.mean = (config.mean_mps * math.cos(to), config.mean_mps * math.sin(to), 0.0)
        sigma = config.gust_mps
        self._sigma = (sigma, sigma, 0.5 * sigma)
        # exact discretisation of dg = -g/tau dt + sigma*sqrt(2/tau) dW over one update
        self._decay = math.exp(-config.update_s / config.tau_s)
        self._kick = math.sqrt(1.0 - self._decay ** 2)
        self.gust = tuple(float(s * rng.standard_normal()) for s in self._sigma)   # start stationary
        self._next_t = 0.0
        self.current = self._sum()

    def _sum(self) -> tuple[float, float, float]:
        return (self.mean[0] + self.gust[0], self.mean[1] + self.gust[1], self.mean[2] + self.gust[2])

    def velocity(self, t: float) -> tuple[float, float, float]:
        while t >= self._next_t:
            self._next_t += self.config.update_s
            d, k = self._decay, self._kick
            noise = self._rng.standard_normal(3)
            self.gust = tuple(float(d * g + k * s * n) for g, s, n in zip(self.gust, self._sigma, noise,
                                                                         strict=True))
            self.current = self._sum()
        return self.current


def parse_wind(text: str) -> WindConfig:
    """'MEAN_MPS,GUST_MPS' or 'MEAN_MPS,GUST_MPS,FROM_DEG' → WindConfig (ValueError with the fix otherwise)."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) not in (2, 3):
        raise ValueError(f"--wind {text!r} must be MEAN_MPS,GUST_MPS or MEAN_MPS,GUST_MPS,FROM_DEG, e.g. 3,1 or "
                         f"3,1,270")
    return WindConfig(values[0], values[1], values[2] if len(values) == 3 else None)
