"""Vehicle-core benchmark: physics + control + estimator steps per second on one core.

Each run takes off (untimed), then times 2 s of simulated flight: hover and a 2 m move with the
trapezoid planner streaming. Reports the median of 5 runs with the noisy estimator on
(``vehicle.steps_per_s``) and with exact-truth state (``vehicle.steps_per_s_no_noise``).
Timed with ``time.process_time`` (CPU seconds of this process): "per second on one core" stays
meaningful on a machine shared with other jobs. Run: ``python -m tools.bench vehicle``.
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from sitl_vehicle.sim import SensorNoise, Setpoint, VehicleConfig, VehicleSim

RUNS = 5
TIMED_S = 2.0


def steps_per_second(noise: SensorNoise | None, runs: int = RUNS, timed_s: float = TIMED_S) -> float:
    rates = []
    for r in range(runs):
        sim = VehicleSim(VehicleConfig(noise=noise), rng=np.random.default_rng(r))
        sim.set_armed(True)
        sim.set_setpoint(Setpoint(position=(0.0, 0.0, -1.5)))
        sim.run(2.0)
        sim.set_setpoint(Setpoint(position=(2.0, 0.0, -1.5)))
        n = int(round(timed_s / sim.dt))
        step = sim.step
        t0 = time.process_time()
        for _ in range(n):
            step()
        rates.append(n / (time.process_time() - t0))
    return statistics.median(rates)


def run() -> dict:
    return {
        "vehicle.steps_per_s": {"value": steps_per_second(SensorNoise()), "unit": "steps/s"},
        "vehicle.steps_per_s_no_noise": {"value": steps_per_second(None), "unit": "steps/s"},
    }


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k}: {v['value']:.0f} {v['unit']}")
