"""Flight-quality acceptance of the vehicle core, driven by Setpoint streams (no MAVLink)."""

import math
from dataclasses import replace

import numpy as np
import pytest

from sitl_vehicle.sim import AIRFRAMES, PlannerConfig, Setpoint, VehicleConfig, VehicleSim

NAN = float("nan")
ALT = -1.5
CORNERS = [(2.0, 0.0, ALT), (2.0, 2.0, ALT), (0.0, 2.0, ALT), (0.0, 0.0, ALT)]
V_MAX = PlannerConfig().v_max_xy


def _stream(sim, sp, duration_s, rate_hz=20.0):
    """Send ``sp`` once, then re-send it identically at ``rate_hz``; record the truth every step."""
    sim.set_setpoint(sp)
    every = int(round(1.0 / (rate_hz * sim.dt)))
    rec = []
    for i in range(int(round(duration_s / sim.dt))):
        if i and i % every == 0:
            sim.set_setpoint(sp)
        sim.step()
        t = sim.truth
        rec.append((*t.position, *t.velocity))
    return np.array(rec)


def fly_square(noise_seed=None, airframe="quad250"):
    """Arm, take off to 1.5 m, fly the 2 m square corner by corner, land. Returns per-leg metrics."""
    cfg = VehicleConfig(airframe=AIRFRAMES[airframe])
    if noise_seed is None:
        cfg = replace(cfg, noise=None)
    sim = VehicleSim(cfg, rng=np.random.default_rng(noise_seed))
    assert sim.landed
    sim.set_armed(True)
    takeoff = _stream(sim, Setpoint(position=(0.0, 0.0, ALT)), 4.0)
    legs = []
    start = np.array([0.0, 0.0, ALT])
    for corner in CORNERS:
        rec = _stream(sim, Setpoint(position=corner), 3.5)
        target = np.array(corner)
        d = target - start
        u = d / np.linalg.norm(d)
        rel = rec[:, :3] - target
        along = rel @ u  # > 0: beyond the corner
        cross = np.linalg.norm(rel - np.outer(along, u), axis=1)
        legs.append({
            "final_error": float(np.linalg.norm(rec[-1, :3] - target)),
            "peak_speed": float(np.max(np.linalg.norm(rec[:, 3:6], axis=1))),
            "overshoot": float(max(np.max(along), 0.0)),
            "max_cross_track": float(np.max(cross)),
            "alt_error": float(np.max(np.abs(rec[:, 2] - ALT))),
        })
        start = target
    restarts = sim.planner.restarts  # take-off + 4 corners; the 20 Hz re-sends never replanned
    # land: hold x, y; descend in velocity (z position NaN)
    land = _stream(sim, Setpoint(position=(0.0, 0.0, NAN), velocity=(NAN, NAN, 0.7)), 4.0)
    return {"sim": sim, "takeoff": takeoff, "legs": legs, "land": land, "restarts": restarts}


@pytest.fixture(scope="module")
def clean_flight():
    return fly_square(None)


@pytest.fixture(scope="module")
def noisy_flight():
    return fly_square(7)


def test_takeoff_reaches_altitude_without_overshoot(clean_flight):
    z = clean_flight["takeoff"][:, 2]
    assert abs(z[-1] - ALT) < 0.05
    assert np.min(z) > ALT - 0.10  # never more than 10 cm above the target altitude


@pytest.mark.parametrize("leg", range(4))
def test_square_corner_accuracy_noise_off(clean_flight, leg):
    m = clean_flight["legs"][leg]
    assert m["final_error"] < 0.05, m
    assert abs(m["peak_speed"] - V_MAX) <= 0.05 * V_MAX, m
    assert m["overshoot"] < 0.10, m
    assert m["max_cross_track"] < 0.10, m
    assert m["alt_error"] < 0.10, m


def test_resent_setpoints_never_restart_the_planner(clean_flight):
    assert clean_flight["restarts"] == 1 + len(CORNERS)


def test_lands_softly_and_is_landed(clean_flight):
    sim = clean_flight["sim"]
    assert sim.landed and not sim.crashed, sim.crash_reason
    assert sim.truth.position[2] == 0.0
    assert np.max(clean_flight["land"][:, 2]) <= 0.0  # never below the ground


# Noise ON (seeded): the controller flies on the Kalman estimate. Looser bounds, stated here:
# corner error < 0.10 m (estimate error + noise-driven motion), peak speed within 10 % of v_max,
# overshoot and cross-track < 0.15 m.
@pytest.mark.parametrize("leg", range(4))
def test_square_corner_accuracy_noise_on(noisy_flight, leg):
    m = noisy_flight["legs"][leg]
    assert m["final_error"] < 0.10, m
    assert abs(m["peak_speed"] - V_MAX) <= 0.10 * V_MAX, m
    assert m["overshoot"] < 0.15, m
    assert m["max_cross_track"] < 0.15, m


def test_noisy_flight_lands(noisy_flight):
    sim = noisy_flight["sim"]
    assert sim.landed and not sim.crashed


def test_tello_flies_the_square_within_the_same_bounds():
    flight = fly_square(None, airframe="tello")
    for m in flight["legs"]:
        assert m["final_error"] < 0.05 and abs(m["peak_speed"] - V_MAX) <= 0.05 * V_MAX and m["overshoot"] < 0.10
    assert flight["sim"].landed and not flight["sim"].crashed


def test_wrong_hover_thrust_is_absorbed_by_the_integrator():
    cfg = VehicleConfig(noise=None)
    cfg = replace(cfg, control=replace(cfg.control, hover_thrust=0.8 * cfg.airframe.hover_thrust))
    sim = VehicleSim(cfg)
    sim.set_armed(True)
    _stream(sim, Setpoint(position=(0.0, 0.0, -1.0)), 6.0)
    assert abs(sim.truth.position[2] + 1.0) < 0.01
    assert sim.pos_ctl.integral[2] < -0.5  # the integrator supplies the missing 20 % of hover thrust


def test_hover_holds_altitude():
    sim = VehicleSim(VehicleConfig(noise=None))
    sim.set_armed(True)
    sp = Setpoint(position=(0.0, 0.0, -1.0))
    _stream(sim, sp, 4.0)
    rec = _stream(sim, sp, 3.0)
    assert np.max(np.abs(rec[:, 2] + 1.0)) < 0.01
    assert np.max(np.abs(rec[:, :2])) < 0.01


def test_disarmed_vehicle_stays_on_ground():
    sim = VehicleSim(VehicleConfig(noise=None), initial_position=(1.0, 2.0, 0.0))
    zs = []
    for _ in range(1000):
        sim.step()
        zs.append(sim.truth.position[2])
    assert max(zs) == 0.0 and sim.landed
    assert sim.truth.position[:2] == (1.0, 2.0)
    assert sim.motor_outputs == (0.0, 0.0, 0.0, 0.0)


def test_armed_without_setpoint_idles_on_ground():
    sim = VehicleSim(VehicleConfig(noise=None))
    sim.set_armed(True)
    sim.run(1.0)
    idle = sim.airframe.idle_command
    assert all(abs(m - idle) < 1e-6 for m in sim.motor_outputs)
    assert sim.landed and sim.truth.position == (0.0, 0.0, 0.0)


def test_disarm_in_air_falls_and_lands_never_below_ground():
    sim = VehicleSim(VehicleConfig(noise=None, crash_speed_mps=100.0), initial_position=(0.0, 0.0, -0.5))
    assert not sim.landed
    zmax = -1.0
    for _ in range(1000):
        sim.step()
        zmax = max(zmax, sim.truth.position[2])
    assert zmax == 0.0 and sim.landed and not sim.crashed


def test_reconfigure_keeps_state():
    from dataclasses import replace

    sim = VehicleSim(VehicleConfig(noise=None))
    sim.set_armed(True)
    _stream(sim, Setpoint(position=(0.0, 0.0, -1.0)), 3.0)
    before = sim.truth
    sim.reconfigure(control=replace(sim.config.control, pos_p_xy=1.0), planner=PlannerConfig(v_max_xy=1.0))
    assert sim.truth == before and sim.config.planner.v_max_xy == 1.0
    rec = _stream(sim, Setpoint(position=(2.0, 0.0, -1.0)), 4.0)
    assert np.max(rec[:, 3]) < 1.05  # the new planner limit applies to the next target
    assert abs(rec[-1, 0] - 2.0) < 0.05


def test_velocity_setpoint_is_acceleration_limited():
    sim = VehicleSim(VehicleConfig(noise=None))
    sim.set_armed(True)
    _stream(sim, Setpoint(position=(0.0, 0.0, -1.0)), 3.0)
    sim.set_setpoint(Setpoint(velocity=(1.5, 0.0, 0.0), yaw=0.0))
    a_max = sim.config.planner.a_max_xy
    vrefs = []
    for _ in range(int(1.5 / sim.dt)):
        sim.step()
        vrefs.append(sim.reference[1][0])
    vrefs = np.array(vrefs)
    dv = np.diff(vrefs[::sim._pos_div]) / sim._pos_dt
    assert np.max(dv) <= a_max * (1 + 1e-6)
    assert abs(vrefs[-1] - 1.5) < 1e-9
    assert abs(sim.truth.velocity[0] - 1.5) < 0.1
    assert all(math.isnan(c) for c in sim.reference[0])  # position not controlled


def test_land_style_setpoint_descends_at_commanded_speed():
    sim = VehicleSim(VehicleConfig(noise=None))
    sim.set_armed(True)
    _stream(sim, Setpoint(position=(1.0, 0.0, -2.0)), 5.0)
    rec = _stream(sim, Setpoint(position=(1.0, 0.0, NAN), velocity=(NAN, NAN, 0.5)), 2.0)
    assert abs(rec[-1, 5] - 0.5) < 0.05  # vz
    assert np.max(np.abs(rec[:, 0] - 1.0)) < 0.02  # x held by position control


def _hovering_sim():
    sim = VehicleSim(VehicleConfig(noise=None))
    sim.set_armed(True)
    _stream(sim, Setpoint(position=(0.0, 0.0, -2.0)), 4.0)
    return sim


@pytest.mark.parametrize("name,sp,check", [
    # velocity xy + position z: moves at the commanded velocity, holds altitude
    ("vel_xy_pos_z", Setpoint(position=(NAN, NAN, -2.0), velocity=(1.0, -0.5, NAN)),
     lambda r: abs(r[-1, 3] - 1.0) < 0.03 and abs(r[-1, 4] + 0.5) < 0.03 and np.max(np.abs(r[:, 2] + 2.0)) < 0.05),
    # position xy + velocity z: climbs at the commanded rate, holds x, y
    ("pos_xy_vel_z", Setpoint(position=(0.0, 0.0, NAN), velocity=(NAN, NAN, -0.5)),
     lambda r: abs(r[-1, 5] + 0.5) < 0.03 and np.max(np.abs(r[:, :2])) < 0.02),
    # velocity only (all three axes)
    ("vel_only", Setpoint(velocity=(0.0, 0.8, 0.3)),
     lambda r: abs(r[-1, 4] - 0.8) < 0.03 and abs(r[-1, 5] - 0.3) < 0.03 and abs(r[-1, 3]) < 0.03),
    # velocity xy + acceleration z = 0 (thrust for level flight, altitude not controlled): stays close
    ("vel_xy_acc_z", Setpoint(velocity=(0.5, 0.0, NAN), acceleration=(NAN, NAN, 0.0)),
     lambda r: abs(r[-1, 3] - 0.5) < 0.05 and abs(r[-1, 5]) < 0.3),
])
def test_sim_nan_axes_mean_not_controlled(name, sp, check):
    sim = _hovering_sim()
    rec = _stream(sim, sp, 2.5)
    assert check(rec), (name, rec[-1])
    p_ref, v_ref, _ = sim.reference
    for i in range(3):
        assert math.isnan(p_ref[i]) == math.isnan(sp.position[i])  # position reference only where set
        if not math.isnan(sp.velocity[i]):
            assert v_ref[i] == pytest.approx(sp.velocity[i])


def test_incomplete_setpoint_is_rejected_by_validity_check():
    sim = _hovering_sim()
    sim.set_setpoint(Setpoint(position=(1.0, NAN, -2.0)))  # x without y: invalid (PX4 semantics)
    sim.run(0.5)
    assert sim.last_position_output is not None and not sim.last_position_output.valid
    assert not sim.crashed


def test_yaw_setpoint_and_yaw_rate():
    sim = _hovering_sim()
    _stream(sim, Setpoint(position=(0.0, 0.0, -2.0), yaw=1.0), 3.0)
    assert sim.truth.euler()[2] == pytest.approx(1.0, abs=0.01)
    _stream(sim, Setpoint(position=(0.0, 0.0, -2.0), yaw_rate=0.5), 2.0)
    assert abs(sim.truth.angular_velocity[2] - 0.5) < 0.05
    _stream(sim, Setpoint(position=(0.0, 0.0, -2.0)), 1.0)  # neither: heading held
    y0 = sim.truth.euler()[2]
    _stream(sim, Setpoint(position=(0.0, 0.0, -2.0)), 1.0)
    assert abs(sim.truth.euler()[2] - y0) < 0.02


def test_reconfigure_position_rate_with_estimator_keeps_flying():
    from dataclasses import replace

    sim = VehicleSim(VehicleConfig(), rng=np.random.default_rng(2))
    sim.set_armed(True)
    _stream(sim, Setpoint(position=(0.0, 0.0, -1.0)), 3.0)
    sim.reconfigure(control=replace(sim.config.control, position_hz=50.0))
    assert sim._pos_div == 10 and sim.estimator.dt == pytest.approx(0.02)
    rec = _stream(sim, Setpoint(position=(1.0, 0.0, -1.0)), 3.0)
    assert abs(rec[-1, 0] - 1.0) < 0.05 and math.dist(sim.estimate.position, sim.truth.position) < 0.03


def test_attitude_setpoints_fly_stabilized_and_position_control_takes_over_after():
    """Stabilized flight: a centred throttle gives hover thrust, a nose-down pitch accelerates forward; a
    position setpoint afterwards brings the vehicle to a stop where it is told."""
    from sitl_vehicle.sim import AttitudeSetpoint, throttle_to_thrust

    assert throttle_to_thrust(0.0, 0.4, 0.1, 1.0) == pytest.approx(0.1)
    assert throttle_to_thrust(0.5, 0.4, 0.1, 1.0) == pytest.approx(0.4)
    assert throttle_to_thrust(1.0, 0.4, 0.1, 1.0) == pytest.approx(1.0)
    sim = VehicleSim(replace(VehicleConfig(), noise=None))
    sim.set_armed(True)
    sim.set_setpoint(AttitudeSetpoint(throttle=0.0))
    sim.run(1.0)
    assert sim.landed  # low throttle: stays on the ground
    sim.set_setpoint(AttitudeSetpoint(throttle=0.6))
    sim.run(1.0)
    assert -sim.truth.position[2] > 0.3 and sim.truth.velocity[2] < -0.5    # above hover thrust: climbing
    sim.set_setpoint(AttitudeSetpoint(throttle=0.5))
    sim.run(0.3)
    vz = sim.truth.velocity[2]
    sim.run(1.0)
    assert abs(sim.truth.velocity[2] - vz) < 0.5   # hover thrust balances gravity: only drag slows the climb
    sim.set_setpoint(AttitudeSetpoint(pitch=-0.2, throttle=0.52))
    sim.run(1.5)
    assert sim.truth.velocity[0] > 1.0 and abs(sim.truth.position[1]) < 0.2   # forward (north), no drift east
    roll, pitch, _ = sim.truth.euler()
    assert pitch == pytest.approx(-0.2, abs=0.03) and abs(roll) < 0.03
    target = (sim.truth.position[0] + 3.0, 0.0, -2.0)
    sim.set_setpoint(Setpoint(position=target))
    sim.run(8.0)
    assert math.dist(sim.truth.position, target) < 0.05
    assert math.hypot(*sim.truth.velocity) < 0.05 and not sim.crashed
