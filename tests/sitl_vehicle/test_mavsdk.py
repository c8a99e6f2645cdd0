"""A real client: the `mavsdk` package's native (4.x) API flies the vehicle as it would fly PX4 SITL."""

from __future__ import annotations

import dataclasses
import math
import socket
import threading
import time

import pytest

mavsdk = pytest.importorskip("mavsdk")
from mavsdk.plugins.action import Action  # noqa: E402
from mavsdk.plugins.manual_control import ManualControl  # noqa: E402
from mavsdk.plugins.mission import Mission, MissionItem, MissionPlan  # noqa: E402
from mavsdk.plugins.offboard import Offboard, PositionNedYaw  # noqa: E402
from mavsdk.plugins.param import Param  # noqa: E402
from mavsdk.plugins.telemetry import FlightMode, Telemetry  # noqa: E402

from sitl_vehicle.server import ServerConfig, VehicleServer  # noqa: E402
from sitl_vehicle.sim import VehicleConfig  # noqa: E402


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(predicate, timeout: float, what: str):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


@pytest.fixture
def px4_system():
    """The vehicle on an ephemeral port and a MAVSDK ground station connected to it: (server, system)."""
    port = free_udp_port()
    config = ServerConfig(vehicle=dataclasses.replace(VehicleConfig(), noise=None),
                          gcs_local=("127.0.0.1", 0), gcs_remote=None, api_local=("127.0.0.1", 0),
                          api_remote=("127.0.0.1", port), truth_remote=None, speed=3.0)
    server = VehicleServer(config).start()
    sdk = mavsdk.Mavsdk(mavsdk.Configuration.create_with_component_type(mavsdk.ComponentType.GROUND_STATION))
    try:
        assert sdk.add_any_connection(f"udpin://127.0.0.1:{port}") == mavsdk.ConnectionResult.SUCCESS
        system = sdk.first_autopilot(10.0)
        assert system is not None, "MAVSDK did not discover the vehicle as an autopilot"
        assert system.autopilot_type() == mavsdk.Autopilot.PX4
        yield server, system
    finally:
        sdk.destroy()
        server.stop()


def test_mavsdk_connect_health_arm_takeoff_offboard_return_land(px4_system):
    server, system = px4_system
    telemetry, action, offboard = Telemetry(system), Action(system), Offboard(system)
    wait_for(telemetry.health_all_ok, 15, "MAVSDK health all OK")
    health = telemetry.health()
    assert health.is_home_position_ok and health.is_local_position_ok and health.is_armable

    action.set_takeoff_altitude(1.5)
    assert abs(action.get_takeoff_altitude() - 1.5) < 1e-3
    action.arm()
    wait_for(telemetry.armed, 5, "armed telemetry")
    action.takeoff()
    wait_for(lambda: abs(telemetry.position_velocity_ned().position.down_m + 1.5) < 0.1, 20, "takeoff altitude")

    offboard.set_position_ned(PositionNedYaw(0.0, 0.0, -1.5, 0.0))
    offboard.start()
    wait_for(lambda: telemetry.flight_mode() == FlightMode.OFFBOARD, 5, "offboard mode")
    offboard.set_position_ned(PositionNedYaw(1.0, -0.5, -1.5, 0.0))
    wait_for(lambda: _near(telemetry.position_velocity_ned().position, (1.0, -0.5, -1.5), 0.05), 20,
             "offboard position")
    assert _near(server.sim.truth.position, (1.0, -0.5, -1.5), 0.06)

    offboard.stop()  # MAVSDK switches to Hold
    action.set_return_to_launch_altitude(2.0)                     # RTL_RETURN_ALT
    assert abs(action.get_return_to_launch_altitude() - 2.0) < 1e-3
    Param(system).set_param_float("RTL_DESCEND_ALT", 1.0)
    Param(system).set_param_float("RTL_LAND_DELAY", -1.0)           # wait over home until told to land
    action.return_to_launch()
    wait_for(lambda: telemetry.flight_mode() == FlightMode.RETURN_TO_LAUNCH, 5, "return mode")
    wait_for(lambda: _near(telemetry.position_velocity_ned().position, (0.0, 0.0, -1.0), 0.1), 30,
             "return home to RTL_DESCEND_ALT")
    action.land()
    wait_for(lambda: not telemetry.armed(), 40, "landing and auto-disarm")
    assert server.sim.truth.position[2] > -0.05 and not server.sim.crashed


def test_mavsdk_sets_and_reads_integer_parameters_as_on_px4(px4_system):
    """PX4 keeps enumerations as INT32 and MAVSDK reads them bytewise: set_param_int works, a float is the wrong
    type (MAVSDK refuses it and the vehicle keeps its value)."""
    server, system = px4_system
    param = Param(system)
    param.set_param_int("RTL_TYPE", 2)
    assert param.get_param_int("RTL_TYPE") == 2 and server.params["RTL_TYPE"] == 2.0
    assert param.get_param_int("SYS_AUTOSTART") == 4001
    with pytest.raises(mavsdk.plugins.param.ParamError, match="WRONG_TYPE"):
        param.set_param_float("RTL_TYPE", 1.0)
    assert server.params["RTL_TYPE"] == 2.0 and param.get_param_float("MIS_TAKEOFF_ALT") == pytest.approx(2.5)
    every = param.get_all_params()
    assert {"RTL_TYPE", "GF_ACTION", "NAV_DLL_ACT"} <= {p.name for p in every.int_params}
    assert "RTL_RETURN_ALT" in {p.name for p in every.float_params}


def test_mavsdk_manual_control_position_and_altitude_modes(px4_system):
    """MAVSDK's manual_control example: stream joystick input, start Position control, arm, climb, switch to
    Altitude control, land."""
    server, system = px4_system
    telemetry, action, manual = Telemetry(system), Action(system), ManualControl(system)
    sticks = [0.0, 0.0, 0.5, 0.0]  # x pitch, y roll, z throttle (0.5 = centre), r yaw
    stop = threading.Event()

    def send_sticks():
        while not stop.wait(0.05):  # MAVSDK wants the input sent at 10 Hz or more
            manual.set_manual_control_input(*sticks)

    sender = threading.Thread(target=send_sticks, daemon=True)
    try:
        wait_for(telemetry.health_all_ok, 15, "MAVSDK health all OK")
        sender.start()
        time.sleep(0.3)
        manual.start_position_control()
        wait_for(lambda: telemetry.flight_mode() == FlightMode.POSCTL, 5, "Position mode")
        action.arm()
        wait_for(telemetry.armed, 5, "armed telemetry")
        sticks[2] = 0.9
        wait_for(lambda: telemetry.position_velocity_ned().position.down_m < -1.2, 20, "climb on throttle")
        sticks[2] = 0.5
        manual.start_altitude_control()
        wait_for(lambda: telemetry.flight_mode() == FlightMode.ALTCTL, 5, "Altitude mode")
        sticks[0] = 0.5  # forward tilt: Altitude mode accelerates north
        wait_for(lambda: server.sim.truth.velocity[0] > 0.5, 10, "forward flight in Altitude mode")
        sticks[0] = 0.0
        time.sleep(1.2)  # as on PX4, a stick still moving when Land starts would take over (COM_RC_OVERRIDE)
        action.land()
        wait_for(lambda: not telemetry.armed(), 40, "landing and auto-disarm")
        assert not server.sim.crashed
    finally:
        stop.set()
        sender.join(timeout=2)


def test_mavsdk_mission_upload_download_fly_and_land(px4_system):
    """MAVSDK's mission example: upload waypoints, download them, arm, start (PX4 takes off by itself), wait
    until finished, land."""
    server, system = px4_system
    telemetry, action, mission = Telemetry(system), Action(system), Mission(system)
    home = server.config.home
    points = [(2.0, 0.0, 1.5), (2.0, 2.0, 2.0), (0.0, 2.0, 2.0)]
    items = []
    for north, east, up in points:
        lat, lon, _ = home.to_global((north, east, 0.0))
        items.append(MissionItem(latitude_deg=lat, longitude_deg=lon, relative_altitude_m=up, is_fly_through=False))
    wait_for(telemetry.health_all_ok, 15, "MAVSDK health all OK")
    mission.upload_mission(MissionPlan(items))
    downloaded = mission.download_mission().mission_items
    assert len(downloaded) == 3
    assert abs(downloaded[1].latitude_deg - items[1].latitude_deg) < 1e-6
    assert abs(downloaded[1].relative_altitude_m - 2.0) < 1e-3
    action.arm()
    mission.start_mission()
    wait_for(lambda: telemetry.flight_mode() == FlightMode.MISSION, 5, "Mission mode")
    wait_for(mission.is_mission_finished, 60, "the mission to finish")
    assert _near(server.sim.truth.position, (0.0, 2.0, -2.0), 0.15)
    action.land()
    wait_for(lambda: not telemetry.armed(), 30, "landing and auto-disarm")
    assert _near(server.sim.truth.position, (0.0, 2.0, 0.0), 0.15) and not server.sim.crashed


def test_mavsdk_mission_with_speed_loiter_camera_and_gimbal_items(px4_system):
    """The items MAVSDK adds for a mission item's speed, loiter time, gimbal and camera action are accepted, read
    back whole, and flown: the speed from the item on, the loiter held, the payload items flown past."""
    server, system = px4_system
    telemetry, action, mission = Telemetry(system), Action(system), Mission(system)
    home = server.config.home
    (lat0, lon0, _), (lat1, lon1, _) = home.to_global((1.0, 0.0, 0.0)), home.to_global((4.0, 0.0, 0.0))
    items = [MissionItem(latitude_deg=lat0, longitude_deg=lon0, relative_altitude_m=1.5, is_fly_through=False,
                         speed_m_s=0.6, loiter_time_s=1.0, gimbal_pitch_deg=-30.0, gimbal_yaw_deg=0.0,
                         camera_action=MissionItem.CameraAction.TAKE_PHOTO),
             MissionItem(latitude_deg=lat1, longitude_deg=lon1, relative_altitude_m=1.5, is_fly_through=False)]
    wait_for(telemetry.health_all_ok, 15, "MAVSDK health all OK")
    mission.upload_mission(MissionPlan(items))
    downloaded = mission.download_mission().mission_items
    assert len(downloaded) == 2 and abs(downloaded[0].speed_m_s - 0.6) < 1e-3
    assert abs(downloaded[0].loiter_time_s - 1.0) < 1e-3 and abs(downloaded[0].gimbal_pitch_deg + 30.0) < 1e-3
    assert downloaded[0].camera_action == MissionItem.CameraAction.TAKE_PHOTO
    action.arm()
    mission.start_mission()
    speeds = []
    while not mission.is_mission_finished():
        assert len(speeds) < 2000, "the mission did not finish"
        north = server.sim.truth.position[0]
        if 1.8 < north < 3.2:                                   # the leg after the speed change, away from its ends
            speeds.append(math.hypot(*server.sim.truth.velocity[:2]))
        time.sleep(0.02)
    assert speeds and max(speeds) < 0.7
    # the last item is MAVSDK's gimbal release: the vehicle holds at the last waypoint, as PX4 does
    wait_for(lambda: _near(server.sim.truth.position, (4.0, 0.0, -1.5), 0.1), 20, "holding at the last waypoint")


def airborne(system, altitude: float = 1.5) -> tuple[Telemetry, Action]:
    """Health OK, armed and taken off to ``altitude`` above home with MAVSDK's Action plugin."""
    telemetry, action = Telemetry(system), Action(system)
    wait_for(telemetry.health_all_ok, 15, "MAVSDK health all OK")
    action.set_takeoff_altitude(altitude)
    action.arm()
    action.takeoff()
    wait_for(lambda: abs(telemetry.position_velocity_ned().position.down_m + altitude) < 0.1, 20, "takeoff altitude")
    return telemetry, action


def test_mavsdk_goto_location_flies_there_and_holds_facing_the_yaw(px4_system):
    """MAVSDK's Action.goto_location (MAV_CMD_DO_REPOSITION, an AMSL altitude and a yaw in degrees)."""
    server, system = px4_system
    telemetry, action = airborne(system)
    home = server.config.home
    lat, lon, amsl = home.to_global((2.0, -1.0, -2.5))
    action.goto_location(lat, lon, amsl, 90.0)
    wait_for(lambda: telemetry.flight_mode() == FlightMode.HOLD, 5, "Hold mode")
    wait_for(lambda: _near(server.sim.truth.position, (2.0, -1.0, -2.5), 0.1), 30, "the place")
    wait_for(lambda: abs(telemetry.heading().heading_deg - 90.0) < 3.0, 10, "facing east")


def test_mavsdk_do_orbit_flies_round_the_centre_facing_it(px4_system):
    """MAVSDK's Action.do_orbit: MAV_CMD_DO_ORBIT as COMMAND_INT, whose altitude is above sea level (in a frame that
    says relative, as MAVSDK sends it and PX4 reads it)."""
    from mavsdk.plugins.action import OrbitYawBehavior

    server, system = px4_system
    telemetry, action = airborne(system)
    lat, lon, amsl = server.config.home.to_global((3.0, 0.0, -2.0))
    action.do_orbit(2.0, 1.0, OrbitYawBehavior.HOLD_FRONT_TO_CIRCLE_CENTER, lat, lon, amsl)
    assert server.commander.mode.label == "Orbit"

    def round_the_centre(lowest_east: float, highest_east: float) -> bool:
        north, east, down = server.sim.truth.position
        return (abs(math.hypot(north - 3.0, east) - 2.0) < 0.15 and abs(down + 2.0) < 0.1
                and lowest_east <= east <= highest_east)

    wait_for(lambda: round_the_centre(1.5, 2.0), 30, "the circle's east side")      # clockwise from the west:
    wait_for(lambda: round_the_centre(-2.0, -1.5), 30, "its west side")             # north, east, south, west
    heading = telemetry.heading().heading_deg
    north, east, _ = server.sim.truth.position
    assert abs(math.remainder(math.radians(heading) - math.atan2(-east, 3.0 - north), 2 * math.pi)) < 0.15


def test_mavsdk_telemetry_rates_a_script_sets_are_accepted_and_their_streams_come(px4_system):
    """MAVSDK's Telemetry.set_rate_* for the streams PX4 sends on request (the IMU, altitude, odometry, ground truth,
    actuator outputs; RC and rangefinder accepted with nothing to send), each a COMMAND_DENIED error before."""
    server, system = px4_system
    telemetry = Telemetry(system)
    for what in ("imu", "scaled_imu", "altitude", "odometry", "ground_truth", "actuator_output_status", "rc_status",
                 "distance_sensor"):
        getattr(telemetry, f"set_rate_{what}")(10.0)
    wait_for(lambda: abs(telemetry.imu().acceleration_frd.down_m_s2 + 9.81) < 0.05, 5, "the IMU at rest")
    home = server.config.home
    wait_for(lambda: abs(telemetry.ground_truth().latitude_deg - home.lat_deg) < 1e-6, 5, "the ground truth")
    wait_for(lambda: abs(telemetry.altitude().altitude_amsl_m - home.alt_m) < 0.05, 5, "the altitude")


def test_mavsdk_set_current_speed_set_home_and_terminate(px4_system):
    server, system = px4_system
    telemetry, action = airborne(system)
    home = server.config.home
    lat, lon, amsl = home.to_global((12.0, 0.0, -1.5))
    action.goto_location(lat, lon, amsl, 0.0)
    action.set_current_speed(0.7)
    speeds, polls = [], 0
    while server.sim.truth.position[0] < 4.5:           # the speed applies to the move under way, however late
        polls += 1
        assert polls < 1500, "did not move on"
        if server.sim.truth.position[0] > 3.0:
            speeds.append(math.hypot(*server.sim.truth.velocity[:2]))
        time.sleep(0.02)
    assert speeds and max(speeds) < 0.75
    lat, lon, amsl = home.to_global((3.0, 4.0, -1.0))
    action.set_home(False, lat, lon, amsl)
    wait_for(lambda: abs(telemetry.home().latitude_deg - lat) < 1e-6, 5, "the new home")
    assert _near(server.commander.home, (3.0, 4.0, -1.0), 0.01)
    action.terminate()
    wait_for(lambda: not telemetry.armed(), 5, "the motors stopped")


def test_mavsdk_geofence_upload_download_and_clear(px4_system):
    """MAVSDK's Geofence plugin: an inclusion polygon and an exclusion circle go up as a plan of type FENCE, come
    back as they were sent, and are cleared."""
    from mavsdk.plugins.geofence import Circle, FenceType, Geofence, GeofenceData, Point, Polygon

    server, system = px4_system
    home, geofence = server.config.home, Geofence(system)

    def point(north, east):
        lat, lon, _ = home.to_global((north, east, 0.0))
        return Point(latitude_deg=lat, longitude_deg=lon)

    square = Polygon(points=[point(-5, -5), point(-5, 5), point(5, 5), point(5, -5)], fence_type=FenceType.INCLUSION)
    keep_out = Circle(point=point(2, 2), radius=1.0, fence_type=FenceType.EXCLUSION)
    geofence.upload_geofence(GeofenceData(polygons=[square], circles=[keep_out]))
    fence = server.commander.geofence
    assert len(fence.items) == 5 and [z.inclusion for z in fence.zones] == [True, False]
    back = geofence.download_geofence()
    assert len(back.polygons) == 1 and len(back.polygons[0].points) == 4 and len(back.circles) == 1
    assert abs(back.circles[0].radius - 1.0) < 1e-6 and back.circles[0].fence_type == FenceType.EXCLUSION
    assert abs(back.polygons[0].points[2].latitude_deg - square.points[2].latitude_deg) < 1e-6
    geofence.clear_geofence()
    assert server.commander.geofence.items == ()


def _near(position, target, tol) -> bool:
    if hasattr(position, "north_m"):
        position = (position.north_m, position.east_m, position.down_m)
    return all(abs(a - b) < tol for a, b in zip(position, target, strict=True))
