"""The link-fault relay, the edge: UDP sockets and a thread around the pure fault model of
:mod:`tools.link_faults`.

``flowgap-sitl`` with any ``--link-*`` fault starts a :class:`LinkRelay` in its own process before the vehicle
and the companion, and points them through it:

```
 vehicle API 14580+N ─► relay (vehicle side, ephemeral port) ─ faults ─► relay (companion side) ─► 14540+N companion
                      ◄─                                      ◄ faults ─                        ◄─
```

The vehicle's ``--api-remote`` is the relay's vehicle-side socket; the vehicle locks onto it as it locks
onto any peer that answers, and the companion answers the relay's companion-side socket as it answers any
vehicle.  Both sockets bind port 0, so flights at once never share one.

- **Real time**: each datagram enters its direction's :class:`~tools.link_faults.DelayLine` when it arrives and
  leaves when it is due; link time is wall time times the simulation ``speed``, so a 150 ms delay is 150 ms of
  simulated time.  The ground-truth side channel goes straight from the vehicle to the companion.
- **Lockstep**: the relay also sits on the side channel and proxies the lockstep words
  (:mod:`tools.link_lockstep`), so that delays run on simulated time and the message counts in the releases
  and acks stay true to what each side was actually given.
"""

from __future__ import annotations

import errno
import logging
import select
import socket
import threading
import time

from tools.link_faults import COMPANION_TO_VEHICLE, VEHICLE_TO_COMPANION, DelayLine, LinkFaults, count_mavlink_frames

log = logging.getLogger(__name__)

Address = tuple[str, int]
IDLE_WAIT_S = 0.02          # how long a real-time relay sleeps with nothing due (wall seconds)


class RelaySocket:
    """One UDP socket of the relay, facing one side; it sends to ``peer``, fixed or learned from the first
    datagram that arrives (as the vehicle locks onto the first peer that answers; ``learn_peer``: also when a
    first guess is given)."""

    def __init__(self, name: str, host: str = "127.0.0.1", peer: Address | None = None,
                 learn_peer: bool | None = None) -> None:
        self.name = name
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self.sock.setblocking(False)
        self.address: Address = self.sock.getsockname()
        self.peer = peer
        self._learn_peer = peer is None if learn_peer is None else learn_peer

    def fileno(self) -> int:
        return self.sock.fileno()

    def receive_all(self) -> list[bytes]:
        out = []
        while True:
            try:
                data, source = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return out
            except OSError as exc:
                if exc.errno == errno.ECONNREFUSED:      # an earlier send found nobody listening
                    continue
                raise
            if self._learn_peer:
                self.peer, self._learn_peer = source, False
            out.append(data)

    def send(self, data: bytes) -> bool:
        if self.peer is None:
            return False
        try:
            self.sock.sendto(data, self.peer)
            return True
        except OSError as exc:      # nobody listening yet, or a full buffer: the datagram is lost, as on a radio
            log.debug("link relay %s: send to %s:%d failed: %s", self.name, *self.peer, exc)
            return False

    def close(self) -> None:
        self.sock.close()


class LinkRelay:
    """Relays the MAVLink API link between a vehicle and a companion with seeded faults, in both directions.

    ``companion_api``: where the companion listens (``udpin``); ``vehicle_api``: where the vehicle's API link
    is bound (default: learned from its first datagram).  ``lockstep``: also proxy the side channel, whose
    companion end listens at ``companion_truth`` (point the vehicle's ``--truth-remote`` at
    :attr:`vehicle_truth_address`).  ``speed``: simulated seconds per wall second (real time only).
    """

    def __init__(self, faults: LinkFaults, companion_api: Address, *, vehicle_api: Address | None = None,
                 companion_truth: Address | None = None, lockstep: bool = False, speed: float = 1.0,
                 host: str = "127.0.0.1") -> None:
        if faults.seed is None:
            raise ValueError("the relay needs faults with a seed (LinkFaults.with_seed)")
        if lockstep and companion_truth is None:
            raise ValueError("a lockstep relay needs the companion's side-channel address (companion_truth)")
        if not speed > 0:
            raise ValueError(f"speed must be positive, got {speed}")
        self.faults = faults
        self.lockstep = lockstep
        self.speed = float(speed)
        self.lines = {d: DelayLine(faults, d) for d in (VEHICLE_TO_COMPANION, COMPANION_TO_VEHICLE)}
        self.vehicle_api = RelaySocket("vehicle API", host, vehicle_api, learn_peer=True)
        self.companion_api = RelaySocket("companion API", host, companion_api)
        self.vehicle_side = RelaySocket("vehicle side channel", host) if lockstep else None
        self.companion_side = RelaySocket("companion side channel", host, companion_truth) if lockstep else None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._proxy = None
        self.error: str | None = None

    @property
    def vehicle_api_address(self) -> Address:
        """Where the vehicle's API link should send (its ``--api-remote``)."""
        return self.vehicle_api.address

    @property
    def vehicle_truth_address(self) -> Address:
        """Where a lockstep vehicle's side channel should send (its ``--truth-remote``)."""
        if self.vehicle_side is None:
            raise ValueError("only a lockstep relay sits on the side channel")
        return self.vehicle_side.address

    # ---------------------------------------------------------------------------------------- lifecycle
    def start(self) -> LinkRelay:
        if self.lockstep:
            from tools.link_lockstep import LockstepProxy

            self._proxy = LockstepProxy(self.lines, self.vehicle_api, self.companion_api, self.vehicle_side,
                                        self.companion_side, self._stop)
            target = self._proxy.run
        else:
            target = self._run_realtime
        self._thread = threading.Thread(target=self._guarded, args=(target,), name="link-relay", daemon=True)
        self._thread.start()
        log.info("link relay: vehicle -> %s:%d, companion <- %s:%d, %s", *self.vehicle_api_address,
                 *self.companion_api.address, self.describe())
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
        for s in (self.vehicle_api, self.companion_api, self.vehicle_side, self.companion_side):
            if s is not None:
                s.close()

    def __enter__(self) -> LinkRelay:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _guarded(self, target) -> None:
        try:
            target()
        except Exception as exc:  # noqa: BLE001 — the flight goes on without a relay; the verdict says why
            self.error = f"{type(exc).__name__}: {exc}"
            log.exception("link relay failed")

    # ---------------------------------------------------------------------------------------- results
    def describe(self) -> str:
        f = self.faults
        return (f"loss {f.loss:g}, delay {f.delay_ms:g}+U(0,{f.jitter_ms:g}) ms, duplicate {f.duplicate:g}, "
                f"reorder {f.reorder:g}, seed {f.seed}, {'lockstep' if self.lockstep else 'real time'}")

    def report(self) -> dict:
        """The settings and what happened, per direction (the verdict's ``link_faults``)."""
        out = {**self.faults.settings(), "clock": "lockstep" if self.lockstep else "realtime"}
        for direction, line in self.lines.items():
            out[direction] = line.stats.to_dict()
        if self._proxy is not None:
            out["lockstep_releases"] = self._proxy.releases
            out["vehicle_releases"] = self._proxy.vehicle_releases
        if self.error:
            out["error"] = self.error
        return out

    # ---------------------------------------------------------------------------------------- real time
    def _run_realtime(self) -> None:
        wall0 = time.monotonic()

        def link_now() -> float:
            return (time.monotonic() - wall0) * self.speed

        routes = ((self.vehicle_api, self.lines[VEHICLE_TO_COMPANION], self.companion_api),
                  (self.companion_api, self.lines[COMPANION_TO_VEHICLE], self.vehicle_api))
        sockets = [self.vehicle_api, self.companion_api]
        while not self._stop.is_set():
            wait = IDLE_WAIT_S
            for _, line, _ in routes:
                due = line.next_due()
                if due is not None:
                    wait = min(wait, max(0.0, (due - link_now()) / self.speed))
            readable, _, _ = select.select(sockets, [], [], wait)
            for source, line, _ in routes:
                if source in readable:
                    for data in source.receive_all():
                        line.push(data, link_now(), count_mavlink_frames(data))
            now = link_now()
            for _, line, destination in routes:
                for datagram in line.pop_due(now):
                    destination.send(datagram.payload)


def relay_for_instance(faults: LinkFaults, instance: int, lockstep: bool, speed: float = 1.0) -> LinkRelay:
    """A relay for a ``flowgap-sitl`` flight of PX4 instance ``instance`` (companion API 14540+N, side channel
    14560+N, vehicle API 14580+N), not yet started."""
    return LinkRelay(faults, ("127.0.0.1", 14540 + instance), vehicle_api=("127.0.0.1", 14580 + instance),
                     companion_truth=("127.0.0.1", 14560 + instance) if lockstep else None, lockstep=lockstep,
                     speed=speed)
