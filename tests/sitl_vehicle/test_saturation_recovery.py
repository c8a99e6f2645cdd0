"""Motor saturation with attitude priority: an unreachable roll+pitch demand above hover thrust must leave the
motors running with torque in the demanded direction (PX4's sequential desaturation, airmode disabled), so a
vehicle upset while climbing in gusty wind recovers instead of tumbling to the ground.

Regression for the wp_hard46/hard_0999559861 flight: a 0.2 m offboard step in 2 m/s wind saturated roll and
pitch together while the thrust was above hover; the mixer's reduce-only thrust desaturation skipped PX4's
second (half) pass, took the whole ``k_min + k_max`` off the collective, and the roll/pitch passes then zeroed
every motor: no thrust, no torque, the body rates froze and the vehicle fell 2 m (hard ground impact, 5.7 m/s).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sitl_vehicle.airframes import AIRFRAMES
from sitl_vehicle.control.mixer import Mixer
from sitl_vehicle.modes import FlightMode
from sitl_vehicle.server import ServerConfig, VehicleServer
from sitl_vehicle.sim import Setpoint, VehicleConfig, VehicleSim
from sitl_vehicle.wind import WindConfig

QUAD = AIRFRAMES["quad250"]
FULL = 4.0 * QUAD.thrust_max_n


def _tilt(sim: VehicleSim) -> float:
    q = sim.truth.attitude
    return math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (q[1] ** 2 + q[2] ** 2))))


@pytest.mark.parametrize("thrust", [0.6, 0.8, 1.0, 1.2])
@pytest.mark.parametrize("signs", [(1, 1), (1, -1), (-1, 1), (-1, -1)])
def test_an_unreachable_roll_and_pitch_demand_above_hover_keeps_the_motors_running(thrust, signs):
    m = Mixer(QUAD)
    torque = (signs[0] * 0.6, signs[1] * 0.6, 0.0)        # N*m: both axes beyond what the rotors can give
    u = m.mix(thrust * FULL, torque)
    f, tx, ty, _ = m.effectiveness(u)
    assert all(0.0 <= x <= 1.0 for x in u)
    # thrust is reduced (never added), but only to centre the spread between the bounds: half of full here
    assert f == pytest.approx(0.5 * FULL, rel=1e-9)
    assert max(u) == pytest.approx(1.0) and min(u) == pytest.approx(0.0)      # all the authority is used
    assert tx * torque[0] + ty * torque[1] > 0.0                                # torque towards the demand
    assert signs[1] * ty > 0.0                                                  # pitch kept (roll gives way first)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("rates", [(5.0, -5.0), (6.0, 6.0)])
def test_a_body_rate_upset_while_climbing_in_gusty_wind_is_recovered(seed, rates):
    yaw = math.radians(37.0 * seed)
    start = (0.0, 0.0, -3.0)
    sim = VehicleSim(VehicleConfig(wind=WindConfig(2.0, 0.8)), rng=np.random.default_rng(seed),
                     initial_position=start, initial_yaw=yaw)
    sim.set_armed(True)
    sim.set_setpoint(Setpoint(position=start, yaw=yaw))
    sim.run(3.0)
    sim.set_setpoint(Setpoint(position=(0.0, 0.0, -4.0), yaw=yaw))      # climb 1 m: thrust above hover
    sim.run(0.3)
    z0 = sim.truth.position[2]
    sim.dyn.x[10], sim.dyn.x[11] = rates                                # a diagonal roll+pitch upset (rad/s)
    max_tilt = 0.0
    lowest = z0
    for _ in range(int(round(3.0 / sim.dt))):
        sim.step()
        max_tilt = max(max_tilt, _tilt(sim))
        lowest = max(lowest, sim.truth.position[2])
        assert not sim.crashed, sim.crash_reason
    assert math.degrees(max_tilt) < 60.0
    assert lowest - z0 < 0.1                                            # no altitude lost (NED: +z is down)
    assert sim.truth.position[2] == pytest.approx(-4.0, abs=0.15)      # and the climb completed


def test_the_hard_0999559861_offboard_step_in_wind_no_longer_flips():
    """The flight's own timeline (seed, wind, start, setpoints as in its tlog), on the vehicle server's own
    commander, status and 50 Hz tick (its links bound to ephemeral loopback ports and never read)."""
    config = ServerConfig(vehicle=VehicleConfig(wind=WindConfig(2.05, 0.76, 357.8)), seed=1698718304,
                          start_position=(-0.03, -0.837, 0.0), start_yaw=math.radians(-14.004155605080367),
                          params=(("MIS_TAKEOFF_ALT", 1.943),), gcs_local=("127.0.0.1", 0), gcs_remote=None,
                          api_local=("127.0.0.1", 0), api_remote=None, truth_local=("127.0.0.1", 0),
                          truth_remote=None)
    server = VehicleServer(config)
    sim, commander = server.sim, server.commander
    hold = Setpoint(position=(-0.049, -0.842, -1.932), yaw=-0.245)
    step = Setpoint(position=(0.152, -0.869, -1.956), yaw=-0.245)
    armed = offboard = False
    next_tick = 0.0
    max_tilt = 0.0
    z_min_alt = math.inf
    try:
        while sim.time_s < 6.0:
            t = sim.time_s
            if t >= 0.062 and not armed:
                armed = True
                status = server.vehicle_status()
                assert commander.arm(status).accepted and commander.takeoff(status, 1.943).accepted
            if t >= 2.449:
                commander.offboard_setpoint(step if t >= 3.5 - 1e-9 else hold, t)
            if t >= 3.41 and not offboard:
                offboard = True
                assert commander.set_mode(FlightMode.OFFBOARD, server.vehicle_status()).accepted
            if t + 1e-9 >= next_tick:                                   # the server's 50 Hz commander tick
                server.commander_tick()
                next_tick += 1.0 / config.commander_hz
            sim.step()
            if offboard:
                max_tilt = max(max_tilt, _tilt(sim))
                z_min_alt = min(z_min_alt, -sim.truth.position[2])
            assert not sim.crashed, sim.crash_reason
    finally:
        server.close()
    assert math.degrees(max_tilt) < 35.0
    assert z_min_alt > 1.8
    assert sim.truth.position == pytest.approx((0.152, -0.869, -1.956), abs=0.1)
