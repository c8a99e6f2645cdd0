"""SET_POSITION_TARGET_LOCAL_NED → Setpoint: every type_mask group, frames, and malformed values."""

from __future__ import annotations

import itertools
import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.mavlink_io import SetpointError, setpoint_from_message

POS, VEL, ACC = 0b111, 0b111 << 3, 0b111 << 6
YAW, YAW_RATE = 1 << 10, 1 << 11


def message(mask, frame=mavlink.MAV_FRAME_LOCAL_NED, pos=(1.0, 2.0, -3.0), vel=(0.1, 0.2, 0.3),
            acc=(0.01, 0.02, 0.03), yaw=0.5, yaw_rate=0.05):
    return mavlink.MAVLink_set_position_target_local_ned_message(0, 1, 1, frame, mask, *pos, *vel, *acc, yaw, yaw_rate)


@pytest.mark.parametrize("use_pos, use_vel, use_acc, use_yaw, use_rate",
                         [c for c in itertools.product([True, False], repeat=5) if any(c[:3])])
def test_type_mask_maps_each_group_to_nan_or_value(use_pos, use_vel, use_acc, use_yaw, use_rate):
    mask = ((0 if use_pos else POS) | (0 if use_vel else VEL) | (0 if use_acc else ACC)
            | (0 if use_yaw else YAW) | (0 if use_rate else YAW_RATE))
    sp = setpoint_from_message(message(mask), yaw_now=0.0)
    for used, got, want in ((use_pos, sp.position, (1.0, 2.0, -3.0)), (use_vel, sp.velocity, (0.1, 0.2, 0.3)),
                            (use_acc, sp.acceleration, (0.01, 0.02, 0.03))):
        if used:
            assert got == pytest.approx(want)
        else:
            assert all(math.isnan(v) for v in got)
    assert (sp.yaw == pytest.approx(0.5)) if use_yaw else math.isnan(sp.yaw)
    assert (sp.yaw_rate == pytest.approx(0.05)) if use_rate else math.isnan(sp.yaw_rate)


def test_single_axis_masking():
    sp = setpoint_from_message(message(0b100 | VEL | ACC | YAW_RATE), yaw_now=0.0)  # z ignored
    assert sp.position[:2] == pytest.approx((1.0, 2.0)) and math.isnan(sp.position[2])


def test_body_ned_rotates_velocity_by_heading_but_not_position():
    sp = setpoint_from_message(message(ACC | YAW | YAW_RATE, frame=mavlink.MAV_FRAME_BODY_NED, vel=(1.0, 0.0, 0.2)),
                               yaw_now=math.pi / 2)
    assert sp.position == pytest.approx((1.0, 2.0, -3.0))
    assert sp.velocity == pytest.approx((0.0, 1.0, 0.2), abs=1e-9)


@pytest.mark.parametrize("kwargs, fragment", [
    (dict(pos=(math.nan, 0.0, -1.0)), "position x"),
    (dict(vel=(0.0, math.inf, 0.0)), "velocity y"),
    (dict(yaw=math.nan), "yaw"),
])
def test_non_finite_used_fields_are_rejected(kwargs, fragment):
    with pytest.raises(SetpointError, match=fragment):
        setpoint_from_message(message(ACC | YAW_RATE, **kwargs), yaw_now=0.0)


def test_nan_in_an_ignored_field_is_fine():
    sp = setpoint_from_message(message(VEL | ACC | YAW | YAW_RATE, vel=(math.nan,) * 3, yaw=math.nan), yaw_now=0.0)
    assert sp.position == pytest.approx((1.0, 2.0, -3.0))


@pytest.mark.parametrize("frame", [mavlink.MAV_FRAME_GLOBAL_INT, mavlink.MAV_FRAME_LOCAL_ENU,
                                   mavlink.MAV_FRAME_LOCAL_OFFSET_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED])
def test_other_frames_are_refused(frame):
    with pytest.raises(SetpointError, match="frame"):
        setpoint_from_message(message(ACC, frame=frame), yaw_now=0.0)


def test_everything_ignored_and_force_are_refused():
    with pytest.raises(SetpointError, match="nothing to fly"):
        setpoint_from_message(message(POS | VEL | ACC), yaw_now=0.0)
    with pytest.raises(SetpointError, match="force"):
        setpoint_from_message(message(POS | VEL | (1 << 9)), yaw_now=0.0)
    # The force flag with accelerations ignored (0xFF8, common in client code) is a position setpoint.
    sp = setpoint_from_message(message(0xFF8), yaw_now=0.0)
    assert sp.position == pytest.approx((1.0, 2.0, -3.0)) and math.isnan(sp.yaw)
