"""The vehicle process: the simulation core, the commander and the MAVLink links on one clock.

``VehicleServer.run`` is the loop of ``flowgap-vehicle``; tests run the same object in a thread on
ephemeral ports (``start``/``stop``). Simulation time is the only time the vehicle knows: streams,
offboard timeouts and auto-disarm all count in it, as PX4 SITL's lockstep does, and ``speed`` maps wall
time to simulation time.
"""

from __future__ import annotations

import json
import logging
import math
import select
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from sitl_vehicle.commander import Commander, VehicleStatus
from sitl_vehicle.link_signing import LinkSigning
from sitl_vehicle.lockstep import LockstepHold
from sitl_vehicle.mavlink_io import MavlinkVehicleInterface
from sitl_vehicle.params import COMMANDER_PARAMS, ParameterStore, apply_binding, bound_specs
from sitl_vehicle.sim import VehicleConfig, VehicleSim
from sitl_vehicle.telemetry import Home, Telemetry, truth_odometry
from sitl_vehicle.udp_link import UdpLink

log = logging.getLogger(__name__)

Address = tuple[str, int]


@dataclass(frozen=True)
class ServerConfig:
    vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    gcs_local: Address = ("0.0.0.0", 18570)
    gcs_remote: Address | None = ("127.0.0.1", 14550)
    api_local: Address = ("0.0.0.0", 14580)
    api_remote: Address | None = ("127.0.0.1", 14540)
    truth_local: Address = ("0.0.0.0", 0)
    truth_remote: Address | None = ("127.0.0.1", 14560)
    truth_hz: float = 100.0
    commander_hz: float = 50.0
    speed: float = 1.0  # simulation seconds per wall second
    seed: int = 0
    start_position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    start_yaw: float = 0.0
    home: Home = field(default_factory=Home)
    params: tuple[tuple[str, float], ...] = ()  # PX4 parameter overrides applied at boot
    scene: str | None = None
    lockstep: bool = False  # advance only as far as the companion releases (sitl_vehicle.lockstep); no speed
    signing_key: Path | None = None  # PX4 key file (sitl_vehicle.signing): sign every link, drop unsigned input


class VehicleServer:
    def __init__(self, config: ServerConfig, world=None):
        self.config = config
        self._signing_closed = False
        self.scene = config.scene
        self.sim = VehicleSim(config.vehicle, rng=np.random.default_rng(config.seed), world=world,
                              initial_position=config.start_position, initial_yaw=config.start_yaw)
        self.params = ParameterStore(COMMANDER_PARAMS + bound_specs(self._core_configs()))
        self.params.on_change(self._on_param_change)
        for name, value in config.params:
            self.params.set(name, value)
        self.commander = Commander(self.params, home=(0.0, 0.0, 0.0))
        self.interface = MavlinkVehicleInterface(self.commander, self.params, config.home,
                                                 self.vehicle_status, self.telemetry,
                                                 signing=LinkSigning(config.signing_key))
        self.links: list[UdpLink] = []
        try:
            for name, local, remote in (("gcs", config.gcs_local, config.gcs_remote),
                                        ("api", config.api_local, config.api_remote)):
                link = UdpLink(name, local, remote)
                self.links.append(link)
                self.interface.add_link(link)
            self.truth_link = UdpLink("truth", config.truth_local, config.truth_remote)
        except OSError:
            self.close()
            raise
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._announced_crash = False
        self._announced_crossing = False
        self._announced_gate = False
        self.wall_time_s = 0.0
        self.lockstep: LockstepHold | None = None

    def _core_configs(self) -> dict:
        return {"control": self.sim.config.control, "planner": self.sim.config.planner}

    def _on_param_change(self, name: str, value: float) -> None:
        """Controller and planner parameters take effect at once, as PX4's parameter updates do."""
        configs = apply_binding(self._core_configs(), name, value)
        if configs["control"] is not self.sim.config.control or configs["planner"] is not self.sim.config.planner:
            self.sim.reconfigure(control=configs["control"], planner=configs["planner"])
            log.info("parameter %s = %g applied to the %s", name, value, "controller/planner")

    # ------------------------------------------------------------------------------- addresses
    def link(self, name: str) -> UdpLink:
        return next(x for x in self.links if x.name == name)

    def address(self, link: str) -> Address:
        """The local (host, port) a link is bound to — useful with ephemeral ports in tests."""
        if link == "truth":
            return self.truth_link.local_address
        return next(x.local_address for x in self.links if x.name == link)

    # --------------------------------------------------------------------------------- status
    def vehicle_status(self) -> VehicleStatus:
        est = self.sim.estimate
        return VehicleStatus(time_s=self.sim.time_s, position=est.position, velocity=est.velocity,
                             yaw=est.euler()[2], armed=self.sim.armed, landed=self.sim.landed,
                             crashed=self.sim.crashed, position_valid=self.sim.estimate_valid)

    def telemetry(self) -> Telemetry:
        est = self.sim.estimate
        motors = self.sim.motor_outputs
        return Telemetry(time_s=self.sim.time_s, position=est.position, velocity=est.velocity,
                         attitude=est.attitude, angular_velocity=est.angular_velocity, euler=est.euler(),
                         armed=self.sim.armed, landed=self.sim.landed, crashed=self.sim.crashed,
                         mode=self.commander.mode, failsafe=self.commander.failsafe,
                         throttle=sum(motors) / len(motors), imu=self.sim.imu_reading, motors=tuple(motors),
                         truth=self.sim.truth, true_specific_force=self.sim.true_specific_force)

    def verdict(self) -> dict:
        sim = self.sim
        collision = bool(sim.crashed)
        return {
            "scene": self.scene,
            "success": sim.passed and not collision,
            "collision": collision,
            "crash_reason": sim.crash_reason,
            "crossed_wall": sim.crossed_wall,
            "min_clearance_m": _json_float(sim.min_clearance_m),
            "sim_time_s": round(sim.time_s, 4),
            "wall_time_s": round(self.wall_time_s, 3),
            "final_position_ned": [round(v, 4) for v in sim.truth.position],
            "malformed_datagrams": sum(link.malformed_datagrams for link in self.links),
            "signing": self.interface.signing.summary(),
            "setpoints_received": self.interface.setpoints_received,
            "setpoints_rejected": self.interface.setpoints_rejected,
            "clock": "lockstep" if self.config.lockstep else "realtime",
            "wind": None if sim.wind is None else {"mean_mps": sim.wind.config.mean_mps,
                                                   "gust_mps": sim.wind.config.gust_mps,
                                                   "from_deg": round(sim.wind.from_deg, 2)},
            "gate": sim.collision.gate_report(),
        }

    def write_result(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(self.verdict(), indent=2) + "\n")

    # ---------------------------------------------------------------------------------- loop
    def commander_tick(self) -> None:
        out = self.commander.update(self.vehicle_status())
        if out.armed != self.sim.armed:
            self.sim.set_armed(out.armed)
        self.sim.set_setpoint(out.setpoint)
        while self.commander.messages:
            severity, text = self.commander.messages.popleft()
            self.interface.statustext(severity, text)

    def _announce_events(self) -> None:
        sim = self.sim
        if sim.crashed and not self._announced_crash:
            self._announced_crash = True
            log.warning("collision: %s", sim.crash_reason)
            self.interface.statustext(mavlink.MAV_SEVERITY_EMERGENCY, f"Collision: {sim.crash_reason}")
        if sim.crossed_wall and not self._announced_crossing:
            self._announced_crossing = True
            log.info("wall crossed at t=%.2f s", sim.time_s)
            self.interface.statustext(mavlink.MAV_SEVERITY_NOTICE, "Ground truth: wall plane crossed")
        if sim.collision.gate_crossed and not self._announced_gate:
            self._announced_gate = True
            log.info("gate crossed at t=%.2f s", sim.time_s)
            self.interface.statustext(mavlink.MAV_SEVERITY_NOTICE, "Ground truth: gate crossed")

    def advance(self, until_s: float, max_steps: int) -> int:
        """Step physics up to ``until_s`` (at most ``max_steps``), ticking commander and truth on time."""
        sim = self.sim
        dt = sim.dt
        control_period = 1.0 / self.config.commander_hz
        truth_period = 1.0 / self.config.truth_hz
        steps = 0
        while sim.time_s + 0.5 * dt < until_s and steps < max_steps:
            if sim.time_s + 1e-9 >= self._next_control:
                self.commander_tick()
                self._next_control += control_period
            sim.step()
            steps += 1
            if sim.time_s + 1e-9 >= self._next_truth:
                self._next_truth += truth_period
                t = sim.truth
                self.truth_link.send(truth_odometry(sim.time_s, t.position, t.attitude, t.velocity,
                                                    t.angular_velocity))
        return steps

    def run(self, duration_s: float | None = None, stop: threading.Event | None = None) -> dict:
        """Run in (scaled) real time, or in lockstep, until ``stop`` is set or ``duration_s`` of simulation
        has passed."""
        stop = stop or self._stop
        self._next_control = self.sim.time_s
        self._next_truth = self.sim.time_s
        end = math.inf if duration_s is None else self.sim.time_s + duration_s
        wall0 = time.monotonic()
        if self.config.lockstep:
            self._run_lockstep(end, stop)
        else:
            self._run_realtime(end, stop)
        self.wall_time_s = time.monotonic() - wall0
        return self.verdict()

    def _before(self, end: float) -> bool:
        """Whether physics has a step left before ``end``, counted as :meth:`advance` counts them (half a step's
        slack): an end an ulp past the last step, ``time_s < end`` would wait for a step that never comes."""
        return self.sim.time_s + 0.5 * self.sim.dt < end

    def _step_to(self, target: float) -> None:
        """Physics, commander and truth up to ``target``, streams and events at least every 10 ms of it."""
        sim = self.sim
        while self._before(target):
            self.advance(min(target, sim.time_s + 0.01), 1 << 30)
            self.interface.send_streams(sim.time_s)
            self._announce_events()

    def _run_lockstep(self, end: float, stop: threading.Event) -> None:
        """Held until the companion releases time; then read its API messages, run to the release, answer."""
        hold = self.lockstep = LockstepHold(self)
        log.info("lockstep: held at t=%.3f s until a companion releases time", self.sim.time_s)
        while not stop.is_set() and self._before(end):
            release = hold.wait(stop)
            if release is None:
                break
            hold.read_api(release)
            self._step_to(min(release.until_s, end))
            hold.ack(release.sequence)

    def _run_realtime(self, end: float, stop: threading.Event) -> None:
        speed = self.config.speed
        sim = self.sim
        wall0 = time.monotonic()
        wall_ref, sim_ref = wall0, sim.time_s
        batch = max(1, int(0.01 / sim.dt))  # service the sockets at least every 10 ms of simulation
        sockets = [link.sock for link in self.links]
        while not stop.is_set() and self._before(end):
            target = min(sim_ref + (time.monotonic() - wall_ref) * speed, end)
            self.advance(target, batch)
            lag = target - sim.time_s
            if lag > 0.25:  # cannot keep up: slow the clock down rather than jump (PX4 lockstep)
                wall_ref += (lag - 0.25) / speed
            self.interface.poll()
            self.interface.send_streams(sim.time_s)
            self._announce_events()
            if lag <= sim.dt:
                wait = max(0.0, sim.dt / speed)
                select.select(sockets, [], [], min(wait, 0.005))

    # ----------------------------------------------------------------------- thread helpers
    def start(self) -> VehicleServer:
        self._thread = threading.Thread(target=self.run, name="flowgap-vehicle", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)
        self.close()

    def close(self) -> None:
        if not self._signing_closed:  # the signing clock goes back to the key file once, as PX4 at shutdown
            self._signing_closed = True
            self.interface.signing.close()
        for link in self.links:
            link.close()
        if getattr(self, "truth_link", None) is not None:
            self.truth_link.close()


def _json_float(value: float) -> float | None:
    return round(value, 4) if math.isfinite(value) else None
