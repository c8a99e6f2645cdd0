"""Seeded link faults, the pure core: what a lossy telemetry radio does to each datagram, and when it arrives.

``flowgap-sitl --link-loss P --link-delay MS[,JITTER_MS] --link-duplicate P --link-reorder P`` puts a relay
(:mod:`tools.link_relay`, the edge: sockets and a thread) on the MAVLink API link between the companion and the
vehicle.  This module decides what the relay does and keeps no sockets and reads no clock: every time is
passed in, in seconds of *link time* (simulated seconds: wall seconds times ``--speed`` in real time, the
vehicle's clock in lockstep).

The model, per direction and per datagram, in the order the datagrams enter:

- **loss**: dropped with probability ``loss``;
- **delay**: otherwise delivered ``delay + U(0, jitter)`` after it entered (each copy draws its own jitter);
- **duplicate**: with probability ``duplicate`` delivered twice;
- **reorder**: with probability ``reorder`` held back until the next datagram that is not dropped has been
  scheduled, then delivered right after it (no earlier than its own due time); a held datagram with no
  successor goes at its due time plus :data:`HOLD_LIMIT_S`, as a radio's buffer would flush.

Every datagram costs the same five draws from its direction's ``numpy`` Generator, seeded from
``(LINK_SEED_SALT, seed, direction)``, whatever the probabilities: the same seed and the same datagram sequence
give the same decisions, and changing one probability leaves the others' draws where they were.
"""

from __future__ import annotations

import argparse
import bisect
import itertools
import math
from dataclasses import dataclass, field, replace

import numpy as np

VEHICLE_TO_COMPANION = "vehicle_to_companion"
COMPANION_TO_VEHICLE = "companion_to_vehicle"
DIRECTIONS = (VEHICLE_TO_COMPANION, COMPANION_TO_VEHICLE)
LINK_SEED_SALT = 0x4C494E4B            # "LINK": the link's draws never coincide with the vehicle's (same seed)
HOLD_LIMIT_S = 0.5                     # a datagram held for reordering goes at the latest this long after its due
DRAWS_PER_DATAGRAM = 5                 # loss, duplicate, reorder, jitter of the first copy, of the second


class LinkFaultError(ValueError):
    """A fault setting out of range or malformed; its text names the option and a valid example."""


@dataclass(frozen=True)
class LinkFaults:
    """What the link does (probabilities per datagram and direction; delays in milliseconds of link time).
    ``seed`` None: the flight's seed decides (:meth:`with_seed`)."""

    loss: float = 0.0
    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    seed: int | None = None

    def __post_init__(self) -> None:
        for option, value in (("--link-loss", self.loss), ("--link-duplicate", self.duplicate),
                              ("--link-reorder", self.reorder)):
            if not 0.0 <= value <= 1.0:     # (also False for NaN)
                raise LinkFaultError(f"{option} must be a probability between 0 and 1, got {value}: "
                                     f"e.g. {option} 0.3")
        for what, value in (("delay", self.delay_ms), ("jitter", self.jitter_ms)):
            if not (math.isfinite(value) and value >= 0.0):
                raise LinkFaultError(f"--link-delay: the {what} must be a finite number of milliseconds >= 0, "
                                     f"got {value}: e.g. --link-delay 150 or 150,30")
        if self.seed is not None and self.seed < 0:
            raise LinkFaultError(f"--link-seed must be a whole number >= 0, got {self.seed}: e.g. --link-seed 7")

    @property
    def active(self) -> bool:
        """Whether the link does anything at all (if not, no relay is needed)."""
        return any((self.loss, self.delay_ms, self.jitter_ms, self.duplicate, self.reorder))

    def with_seed(self, flight_seed: int) -> LinkFaults:
        """These faults with their seed fixed: the given one, else the flight's."""
        return self if self.seed is not None else replace(self, seed=int(flight_seed))

    def rng(self, direction: str) -> np.random.Generator:
        if self.seed is None:
            raise LinkFaultError("link faults need a seed: call with_seed(the flight's seed) first")
        return np.random.default_rng([LINK_SEED_SALT, self.seed, DIRECTIONS.index(direction) + 1])

    def settings(self) -> dict:
        return {"loss": self.loss, "delay_ms": self.delay_ms, "jitter_ms": self.jitter_ms,
                "duplicate": self.duplicate, "reorder": self.reorder, "seed": self.seed}


@dataclass(frozen=True)
class Fate:
    """One datagram's fate: a delay per copy delivered (none: dropped), and whether it is held for reordering."""

    delays_s: tuple[float, ...]
    held: bool = False

    @property
    def dropped(self) -> bool:
        return not self.delays_s


class FaultModel:
    """Decides each datagram's :class:`Fate` from ``rng`` (one Generator per direction)."""

    def __init__(self, faults: LinkFaults, rng: np.random.Generator) -> None:
        self.faults = faults
        self._rng = rng

    def decide(self) -> Fate:
        f = self.faults
        u = self._rng.random(DRAWS_PER_DATAGRAM)
        if u[0] < f.loss:
            return Fate(())
        copies = 2 if u[1] < f.duplicate else 1
        delays = tuple(float(f.delay_ms + f.jitter_ms * u[3 + k]) * 1e-3 for k in range(copies))
        return Fate(delays, held=bool(u[2] < f.reorder))


@dataclass(eq=False)
class Datagram:
    """A datagram on its way: its bytes, how many MAVLink messages it holds, when it entered, when its delay
    ends (``ready_s``) and when it goes (``due_s``: later while it is held for reordering)."""

    payload: bytes
    messages: int
    sent_s: float
    ready_s: float
    due_s: float = math.nan
    order: int = 0
    held: bool = False


@dataclass
class DirectionStats:
    """What one direction did to its datagrams so far (the verdict's counts)."""

    datagrams_in: int = 0
    dropped: int = 0
    duplicated: int = 0
    reordered: int = 0
    delivered: int = 0               # copies handed on (a duplicated datagram counts twice)
    added_delay_total_s: float = 0.0

    def to_dict(self) -> dict:
        mean = self.added_delay_total_s / self.delivered * 1e3 if self.delivered else None
        return {"datagrams_in": self.datagrams_in, "dropped": self.dropped, "duplicated": self.duplicated,
                "reordered": self.reordered, "delivered": self.delivered,
                "mean_added_delay_ms": None if mean is None else round(mean, 3)}


def _to_microseconds(t: float) -> float:
    """Due times to whole microseconds, as lockstep releases travel (so a release can end exactly on one)."""
    return round(t * 1e6) / 1e6


@dataclass
class DelayLine:
    """One direction of the link: the fault model and the datagrams in flight, ordered by (due time, order)."""

    faults: LinkFaults
    direction: str
    hold_limit_s: float = HOLD_LIMIT_S
    stats: DirectionStats = field(default_factory=DirectionStats)

    def __post_init__(self) -> None:
        self.model = FaultModel(self.faults, self.faults.rng(self.direction))
        self._queue: list[tuple[float, int, Datagram]] = []
        self._held: list[Datagram] = []
        self._orders = itertools.count()

    def push(self, payload: bytes, sent_s: float, messages: int = 1) -> Fate:
        """A datagram enters at link time ``sent_s``; returns its fate (for tests and logs)."""
        self.stats.datagrams_in += 1
        fate = self.model.decide()
        if fate.dropped:
            self.stats.dropped += 1
            return fate
        if len(fate.delays_s) > 1:
            self.stats.duplicated += 1
        copies = []
        for delay in fate.delays_s:
            ready = _to_microseconds(sent_s + delay)
            copies.append(Datagram(payload, messages, sent_s, ready, due_s=ready, held=fate.held))
        if not fate.held:
            for copy in copies:
                self._insert(copy)
        released, self._held = self._held, []
        for copy in released:                 # "after the next one": no earlier than it, and behind it
            self._remove(copy)
            copy.due_s, copy.held = max(copy.ready_s, *(c.ready_s for c in copies)), False
            self._insert(copy)
        if fate.held:
            self.stats.reordered += 1
            for copy in copies:
                copy.due_s = _to_microseconds(copy.ready_s + self.hold_limit_s)
                self._insert(copy)
            self._held = copies
        return fate

    def next_due(self) -> float | None:
        return self._queue[0][0] if self._queue else None

    def pop_due(self, now_s: float) -> list[Datagram]:
        """The datagrams due by link time ``now_s``, in order; counted as delivered at ``now_s``."""
        out = []
        while self._queue and self._queue[0][0] <= now_s + 1e-9:
            _, _, datagram = self._queue.pop(0)
            if datagram.held:                 # its successor never came: the radio flushes it
                self._held = [c for c in self._held if c is not datagram]
            out.append(datagram)
            self.stats.delivered += 1
            self.stats.added_delay_total_s += now_s - datagram.sent_s
        return out

    def __len__(self) -> int:
        return len(self._queue)

    def _insert(self, datagram: Datagram) -> None:
        datagram.order = next(self._orders)
        bisect.insort(self._queue, (datagram.due_s, datagram.order, datagram), key=lambda e: e[:2])

    def _remove(self, datagram: Datagram) -> None:
        self._queue = [e for e in self._queue if e[2] is not datagram]


def count_mavlink_frames(data: bytes) -> int:
    """How many MAVLink v1/v2 frames a datagram holds, by their headers (no checksum: the relay forwards the
    bytes unchanged, so the receiver counts what this counts); stray bytes are skipped."""
    count, i, n = 0, 0, len(data)
    while i < n:
        magic = data[i]
        if magic == 0xFD and i + 10 <= n:
            size = 12 + data[i + 1] + (13 if data[i + 2] & 0x01 else 0)
        elif magic == 0xFE and i + 6 <= n:
            size = 8 + data[i + 1]
        else:
            i += 1
            continue
        if i + size > n:
            break
        count += 1
        i += size
    return count


def mavlink_message_id(data: bytes) -> int | None:
    """The message id of the first MAVLink frame in ``data`` (by its header), or None."""
    if len(data) >= 10 and data[0] == 0xFD:
        return data[7] | data[8] << 8 | data[9] << 16
    if len(data) >= 6 and data[0] == 0xFE:
        return data[5]
    return None


# --------------------------------------------------------------------------------------------- command line
def add_link_fault_arguments(parser: argparse.ArgumentParser) -> None:
    """The ``--link-*`` options, the same on ``flowgap-sitl`` and ``flowgap-eval-flights`` (values checked by
    :func:`link_faults_from_args`, so that a bad one is one line, not a usage block)."""
    g = parser.add_argument_group(
        "link faults", "a lossy telemetry radio on the companion's MAVLink API link, both directions\n"
                       "(delays in simulated milliseconds; the ground-truth side channel is never touched)")
    g.add_argument("--link-loss", metavar="P", help="probability that each datagram is lost (e.g. 0.3)")
    g.add_argument("--link-delay", metavar="MS[,JITTER_MS]",
                   help="one-way delay in milliseconds, plus a uniform 0..JITTER_MS (e.g. 150 or 150,30)")
    g.add_argument("--link-duplicate", metavar="P", help="probability that a datagram arrives twice")
    g.add_argument("--link-reorder", metavar="P",
                   help="probability that a datagram is held back and arrives after the next one")
    g.add_argument("--link-seed", metavar="N",
                   help="seed of the link's draws (default: derived from the flight's seed)")


def _probability(option: str, text: str | None) -> float:
    if text is None:
        return 0.0
    try:
        value = float(text)
    except ValueError:
        raise LinkFaultError(f"{option} {text!r} is not a number: give a probability between 0 and 1, "
                             f"e.g. {option} 0.3") from None
    return value


def parse_delay(text: str | None) -> tuple[float, float]:
    """``MS[,JITTER_MS]`` -> (delay ms, jitter ms); LinkFaultError naming the fix."""
    if text is None:
        return 0.0, 0.0
    parts = [p.strip() for p in text.split(",")]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) not in (1, 2):
        raise LinkFaultError(f"--link-delay {text!r} must be MS or MS,JITTER_MS in milliseconds, "
                             f"e.g. --link-delay 150 or 150,30")
    return values[0], values[1] if len(values) == 2 else 0.0


def link_faults_from_args(args: argparse.Namespace) -> LinkFaults | None:
    """The faults the ``--link-*`` options ask for (None: none asked); LinkFaultError for a bad value."""
    delay_ms, jitter_ms = parse_delay(args.link_delay)
    seed = None
    if args.link_seed is not None:
        try:
            seed = int(args.link_seed)
        except ValueError:
            raise LinkFaultError(f"--link-seed {args.link_seed!r} must be a whole number >= 0, "
                                 f"e.g. --link-seed 7") from None
    faults = LinkFaults(loss=_probability("--link-loss", args.link_loss), delay_ms=delay_ms, jitter_ms=jitter_ms,
                        duplicate=_probability("--link-duplicate", args.link_duplicate),
                        reorder=_probability("--link-reorder", args.link_reorder), seed=seed)
    return faults if faults.active else None
