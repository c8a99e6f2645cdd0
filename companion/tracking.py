"""Temporal consistency of the gap centroid (docs/design.md step 4, paper II.D, eq. 14).

:class:`CentroidFilter` applies the paper's rule with τ_c = 80 px:

- a new centroid within τ_c of the last *used* centroid is accepted;
- a new centroid farther than τ_c is rejected and the last used one is reused;
- no new centroid: the last used one is reused;
- no new centroid and none ever used (or the first frame's jump cannot be judged): ``None`` — the caller
  moves straight forward to build a new parallax baseline.

The very first centroid is accepted (there is nothing to compare it with).

:class:`KalmanCentroidFilter` optionally smooths the accepted centroids with a constant-velocity Kalman
filter (filterpy), gating measurements with the same τ_c rule against its prediction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

Centroid = tuple[float, float]


@dataclass(frozen=True)
class TrackingConfig:
    tau_c_px: float = 80.0


class CentroidFilter:
    """The paper's τ_c rule.  ``update(c_k or None) -> used centroid or None``."""

    def __init__(self, config: TrackingConfig = TrackingConfig()) -> None:
        self.config = config
        self._used: Centroid | None = None
        self.last_accepted: bool = False   # whether the latest update accepted its measurement

    @property
    def used(self) -> Centroid | None:
        """The last centroid used for control (c̃_{k−1} before the next update)."""
        return self._used

    def reset(self) -> None:
        self._used = None
        self.last_accepted = False

    def update(self, c_k: Centroid | None) -> Centroid | None:
        if c_k is not None:
            c_k = (float(c_k[0]), float(c_k[1]))
            if not (math.isfinite(c_k[0]) and math.isfinite(c_k[1])):
                c_k = None
        if c_k is None:
            self.last_accepted = False
            return self._used
        if self._used is None or math.dist(c_k, self._used) <= self.config.tau_c_px:
            self._used = c_k
            self.last_accepted = True
        else:
            self.last_accepted = False
        return self._used


class ConfirmingCentroidFilter(CentroidFilter):
    """The τ_c rule with two safeguards of ours: a first centroid is only used once a second detection within
    τ_c confirms it (one false detection must not become the reference everything else is compared with),
    and when ``reacquire_after`` consecutive fresh detections agree with each other but not with the used
    centroid, the used one is stale and the newest agreeing detection replaces it."""

    def __init__(self, config: TrackingConfig = TrackingConfig(), reacquire_after: int = 2) -> None:
        super().__init__(config)
        self.reacquire_after = reacquire_after
        self._candidates: list[Centroid] = []

    def reset(self) -> None:
        super().reset()
        self._candidates = []

    def seed(self, c: Centroid) -> None:
        """Start from ``c`` as the used centroid (carried over from another filter, already confirmed)."""
        self._used, self._candidates = (float(c[0]), float(c[1])), []

    def update(self, c_k: Centroid | None) -> Centroid | None:
        if c_k is not None and not (math.isfinite(c_k[0]) and math.isfinite(c_k[1])):
            c_k = None
        if c_k is None:
            self.last_accepted = False
            return self._used
        c_k = (float(c_k[0]), float(c_k[1]))
        if self._used is not None and math.dist(c_k, self._used) <= self.config.tau_c_px:
            self._candidates = []
            self._used, self.last_accepted = c_k, True
            return self._used
        # Not consistent with the used centroid (or none yet): collect agreeing candidates.
        if self._candidates and math.dist(c_k, self._candidates[-1]) > self.config.tau_c_px:
            self._candidates = []
        self._candidates.append(c_k)
        needed = 2 if self._used is None else self.reacquire_after
        if len(self._candidates) >= needed:
            self._used, self.last_accepted = c_k, True
            self._candidates = []
        else:
            self.last_accepted = False
        return self._used


@dataclass(frozen=True)
class KalmanConfig:
    tau_c_px: float = 80.0
    dt: float = 1.0                    # one frame step
    measurement_std_px: float = 4.0
    accel_std_px: float = 3.0          # white-acceleration process noise, px / step²
    initial_velocity_std_px: float = 20.0


class KalmanCentroidFilter:
    """Constant-velocity Kalman filter on (u, v) with τ_c gating; same ``update`` contract as the rule."""

    def __init__(self, config: KalmanConfig = KalmanConfig()) -> None:
        from filterpy.common import Q_discrete_white_noise
        from filterpy.kalman import KalmanFilter

        self.config = config
        kf = KalmanFilter(dim_x=4, dim_z=2)         # state [u, du, v, dv]
        dt = config.dt
        kf.F = np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1]], dtype=float)
        kf.H = np.array([[1, 0, 0, 0], [0, 0, 1, 0]], dtype=float)
        kf.R = np.eye(2) * config.measurement_std_px ** 2
        kf.Q = Q_discrete_white_noise(dim=2, dt=dt, var=config.accel_std_px ** 2, block_size=2)
        self._kf = kf
        self._initialised = False
        self._used: Centroid | None = None
        self.last_accepted = False

    @property
    def used(self) -> Centroid | None:
        return self._used

    def reset(self) -> None:
        self._initialised = False
        self._used = None
        self.last_accepted = False

    def update(self, c_k: Centroid | None) -> Centroid | None:
        self.last_accepted = False
        if c_k is not None and not (math.isfinite(c_k[0]) and math.isfinite(c_k[1])):
            c_k = None
        if not self._initialised:
            if c_k is None:
                return None
            kf = self._kf
            kf.x = np.array([c_k[0], 0.0, c_k[1], 0.0])
            s2, v2 = self.config.measurement_std_px ** 2, self.config.initial_velocity_std_px ** 2
            kf.P = np.diag([s2, v2, s2, v2])
            self._initialised = True
            self.last_accepted = True
            self._used = (float(c_k[0]), float(c_k[1]))
            return self._used
        self._kf.predict()
        predicted = (float(self._kf.x[0]), float(self._kf.x[2]))
        if c_k is not None and math.dist(c_k, predicted) <= self.config.tau_c_px:
            self._kf.update(np.array([c_k[0], c_k[1]], dtype=float))
            self.last_accepted = True
        self._used = (float(self._kf.x[0]), float(self._kf.x[2]))
        return self._used
