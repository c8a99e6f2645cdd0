"""Collision monitor against fake worlds: contact -> crash, wall crossing, hard ground impact."""

import math

import pytest

from sitl_vehicle.collision import CollisionMonitor, CollisionWorld, GroundOnly
from sitl_vehicle.sim import Setpoint, VehicleConfig, VehicleSim


class SolidPlane:
    """Everything at x >= x0 is solid."""

    def __init__(self, x0):
        self.wall_x = x0

    def clearance(self, p):
        return self.wall_x - p[0]


class WallWithHole:
    """Thin wall (thickness th) at x0 with a circular hole of radius r around (y, z) = c."""

    def __init__(self, x0=3.0, c=(0.0, -1.5), r=1.0, th=0.05):
        self.wall_x, self.c, self.r, self.th = x0, c, r, th

    def clearance(self, p):
        dx = max(abs(p[0] - (self.wall_x + self.th / 2)) - self.th / 2, 0.0)
        rho = math.hypot(p[1] - self.c[0], p[2] - self.c[1])
        if rho < self.r:
            return math.hypot(dx, self.r - rho)
        return dx


def test_protocol_and_ground_only():
    assert isinstance(GroundOnly(), CollisionWorld) and isinstance(SolidPlane(1.0), CollisionWorld)
    m = CollisionMonitor(None, 0.2)
    assert not m.check((100.0, 0.0, -1.0), 0.0)
    assert m.min_clearance_m == math.inf and not m.crossed_wall and m.wall_x is None


def _fly_to(sim, target, seconds):
    sp = Setpoint(position=target)
    for i in range(int(seconds / sim.dt)):
        if i % 25 == 0:
            sim.set_setpoint(sp)
        sim.step()


def test_flying_into_a_wall_crashes_and_stops_motors():
    sim = VehicleSim(VehicleConfig(noise=None), world=SolidPlane(2.0))
    sim.set_armed(True)
    _fly_to(sim, (0.0, 0.0, -1.0), 3.0)
    assert not sim.crashed
    _fly_to(sim, (5.0, 0.0, -1.0), 3.0)
    assert sim.crashed and "collision" in sim.crash_reason
    assert not sim.armed and sim.motor_command == (0.0, 0.0, 0.0, 0.0)
    assert sim.min_clearance_m <= 0.0
    # the body sphere touched: the centre stopped about one radius before the plane at the crash
    assert sim.collision.crash_time_s is not None
    assert not sim.crossed_wall


def test_flying_through_an_opening_crosses_the_wall_without_contact():
    sim = VehicleSim(VehicleConfig(noise=None), world=WallWithHole())
    sim.set_armed(True)
    _fly_to(sim, (0.0, 0.0, -1.5), 4.0)
    _fly_to(sim, (5.0, 0.0, -1.5), 4.0)
    assert not sim.crashed, sim.crash_reason
    assert sim.crossed_wall
    r = sim.airframe.body_radius_m
    assert sim.min_clearance_m == pytest.approx(1.0 - r, abs=0.05)


def test_monitor_sphere_contact_threshold():
    m = CollisionMonitor(SolidPlane(1.0), body_radius_m=0.2)
    assert not m.check((0.79, 0.0, -1.0), 0.0)
    assert m.min_clearance_m == pytest.approx(0.01)
    assert m.check((0.81, 0.0, -1.0), 0.1)
    assert m.crashed and m.crash_time_s == 0.1
    assert not m.check((2.0, 0.0, -1.0), 0.2)  # latched, no second crash


@pytest.mark.parametrize("height,crash", [(1.0, True), (0.1, False)])
def test_hard_ground_impact_is_a_crash(height, crash):
    sim = VehicleSim(VehicleConfig(noise=None, crash_speed_mps=2.0), initial_position=(0.0, 0.0, -height))
    sim.run(1.0)  # disarmed: free fall
    assert sim.landed
    assert sim.crashed == crash
    if crash:
        assert "ground impact" in sim.crash_reason
