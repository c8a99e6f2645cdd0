"""Wind on the vehicle: the gust process's statistics, drift through drag, a hover leaning into it, and still air
leaving today's flight exactly as it was."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from sitl_vehicle.airframes import AIRFRAMES, GRAVITY
from sitl_vehicle.dynamics import QuadDynamics
from sitl_vehicle.sim import Setpoint, VehicleConfig, VehicleSim
from sitl_vehicle.wind import WindConfig, WindModel, parse_wind

QUAD = AIRFRAMES["quad250"]


def test_the_mean_blows_away_from_where_it_comes_from():
    for from_deg, expected in ((0.0, (-3.0, 0.0)), (90.0, (0.0, -3.0)), (270.0, (0.0, 3.0))):
        wind = WindModel(WindConfig(3.0, 0.0, from_deg), np.random.default_rng(1))
        v = wind.velocity(5.0)
        assert v[0] == pytest.approx(expected[0], abs=1e-9) and v[1] == pytest.approx(expected[1], abs=1e-9)
        assert v[2] == 0.0
    drawn = [WindModel(WindConfig(2.0, 0.0), np.random.default_rng(s)).from_deg for s in range(5)]
    assert len(set(drawn)) == 5 and all(0 <= d < 360 for d in drawn)
    assert WindModel(WindConfig(2.0, 0.0), np.random.default_rng(3)).from_deg == drawn[3]   # seeded


def test_gusts_have_the_asked_spread_and_correlation_time():
    config = WindConfig(0.0, 1.5, 0.0, tau_s=2.0, update_s=0.02)
    wind = WindModel(config, np.random.default_rng(7))
    samples = np.array([wind.velocity(t) for t in np.arange(0.0, 4000.0, 0.02)])
    std = samples.std(axis=0)
    assert std[0] == pytest.approx(1.5, rel=0.1) and std[1] == pytest.approx(1.5, rel=0.1)
    assert std[2] == pytest.approx(0.75, rel=0.1)
    lag = int(2.0 / 0.02)                     # one correlation time: correlation e^-1
    x = samples[:, 0] - samples[:, 0].mean()
    assert float(np.dot(x[:-lag], x[lag:]) / np.dot(x, x)) == pytest.approx(math.exp(-1.0), abs=0.08)


def test_a_free_body_drifts_with_the_air_through_its_drag():
    dyn = QuadDynamics(QUAD, 0.002, position=(0.0, 0.0, -5.0))
    dyn.wind = (0.0, 3.0, 0.0)
    hover = QUAD.hover_thrust
    for _ in range(1000):                      # 2 s, level, thrust balancing gravity
        dyn.step((hover,) * 4)
    c_over_m = QUAD.drag_coeff_ns_per_m[1] / QUAD.mass_kg
    expected = 3.0 * (1.0 - math.exp(-c_over_m * 2.0))    # dv/dt = (c/m)(w - v)
    assert dyn.velocity[1] == pytest.approx(expected, rel=0.02)
    assert abs(dyn.velocity[0]) < 1e-6 and dyn.position[1] > 0


def _hover(wind: WindConfig | None, seconds: float = 14.0, seed: int = 0):
    sim = VehicleSim(replace(VehicleConfig(), noise=None, wind=wind), rng=np.random.default_rng(seed))
    sim.set_armed(True)
    target = (0.0, 0.0, -1.5)
    track = []
    every = int(round(0.05 / sim.dt))
    for i in range(int(round(seconds / sim.dt))):
        if i % every == 0:
            sim.set_setpoint(Setpoint(position=target, yaw=0.0))
        sim.step()
        t = sim.truth
        track.append((*t.position, *sim.dyn.attitude))
    return np.array(track)


def test_a_hovering_vehicle_leans_into_a_steady_wind_and_holds_its_place():
    calm = _hover(None)
    windy = _hover(WindConfig(3.0, 0.0, 270.0))           # from the west: the air moves east (+y)
    last = windy[-2000:]                                   # the last 4 s, after the integrator took the load
    qw, qx = last[:, 3], last[:, 4]
    roll = 2.0 * np.arctan2(qx, qw)
    # holding against c·w of drag needs a tilt of atan(c·w / (m·g)), rolled towards the west (negative roll
    # in FRD tilts the thrust to -y)
    lean = math.atan(QUAD.drag_coeff_ns_per_m[1] * 3.0 / (QUAD.mass_kg * GRAVITY))
    assert float(np.median(roll)) == pytest.approx(-lean, abs=0.01)
    assert np.abs(last[:, 1]).max() < 0.05               # and stays over its setpoint
    # while it built up, the wind pushed it downwind, which still air never does
    assert windy[:, 1].max() > 0.02 and np.abs(calm[:, 1]).max() < 1e-6


def test_gusts_move_a_hovering_vehicle_more_the_stronger_they_are():
    spread = [float(np.std(_hover(WindConfig(0.0, g, 0.0), seconds=20.0)[-7500:, :2])) for g in (0.5, 2.0)]
    assert spread[1] > 2.5 * spread[0] > 0


def test_still_air_is_todays_flight_exactly():
    base = _hover(None, seconds=6.0, seed=4)
    for calm in (WindConfig(), WindConfig(0.0, 0.0, 90.0)):
        assert np.array_equal(_hover(calm, seconds=6.0, seed=4), base)
    noisy = replace(VehicleConfig(), wind=None)
    a = VehicleSim(noisy, rng=np.random.default_rng(2))
    b = VehicleSim(replace(noisy, wind=WindConfig(2.0, 1.0)), rng=np.random.default_rng(2))
    a.set_armed(True)
    b.set_armed(True)
    for sim in (a, b):
        sim.set_setpoint(Setpoint(position=(0.0, 0.0, -1.0), yaw=0.0))
        for _ in range(200):
            sim.step()
    # the wind draws from its own child of the seed: the sensor noise stays the same draw for draw
    assert a.estimate.position != b.estimate.position
    assert a.imu.gyro((0.0, 0.0, 0.0)) == b.imu.gyro((0.0, 0.0, 0.0))


@pytest.mark.parametrize("text, needle", [("3", "MEAN_MPS,GUST_MPS"), ("a,b", "MEAN_MPS,GUST_MPS"),
                                          ("-1,0", "mean_mps must be a finite number >= 0"),
                                          ("1,nan", "gust_mps must be a finite number >= 0")])
def test_bad_wind_is_refused_with_the_fix(text, needle):
    with pytest.raises(ValueError, match=needle):
        parse_wind(text)
    assert parse_wind("3,1,270") == WindConfig(3.0, 1.0, 270.0) and parse_wind("3,1").from_deg is None
