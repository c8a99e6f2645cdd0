"""The companion's time: every wait, timeout and rate in the link and the mission reads one ``Clock``.

``WallClock`` is the real world's time (``time.monotonic``), what a companion flying a real PX4 uses.
``LockstepClock`` is the simulated vehicle's time: the vehicle (``flowgap-vehicle --lockstep``) advances only
when this clock releases it, over the simulation-only side channel (:mod:`companion.lockstep`), never over
the MAVLink API link.  It releases the vehicle only when every thread that waits on it (the mission and the
link's setpoint stream) is waiting, and then wakes them one at a time in a fixed order, so a flight is a
function of its inputs, not of how fast this machine is: perception costs no simulated time, however long
it takes.

Both clocks serve the same calls: ``now``, ``sleep``, ``sleep_until``, ``wait_for``; ``spawn`` starts a thread
that waits on the clock; ``attach_link`` hands the clock a link's receive function (a thread of its own on the
wall clock; called after each release until the vehicle's messages are all in, on the lockstep clock) and its
count of messages sent (the lockstep vehicle reads them all before it moves on).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Protocol

log = logging.getLogger(__name__)

# A receiver reads what is waiting (blocking at most ``timeout_s``) and returns how many messages it took.
Receiver = Callable[[float], int]


class ClockThread:
    """A thread started by ``Clock.spawn``, which runs ``target(this)``: ``stop()`` sets ``stopped`` and ends
    its waits at once, then ``join()``."""

    def __init__(self, clock: Clock, target: Callable[[ClockThread], None], name: str) -> None:
        self._clock = clock
        self.stopped = threading.Event()
        self.thread = threading.Thread(target=self._run, args=(target,), name=name, daemon=True)

    def _run(self, target: Callable[[ClockThread], None]) -> None:
        try:
            target(self)
        finally:
            self._clock._thread_ended()

    def stop(self) -> None:
        self.stopped.set()
        self._clock._thread_stopped(self.thread)

    def join(self, timeout: float | None = None) -> None:
        self.thread.join(timeout)


class Clock(Protocol):
    def now(self) -> float: ...

    def sleep(self, seconds: float) -> None: ...

    def sleep_until(self, t: float) -> None: ...

    def wait_for(self, predicate: Callable[[], bool], timeout_s: float, period_s: float = 0.02) -> bool: ...

    def spawn(self, target: Callable[[ClockThread], None], name: str) -> ClockThread: ...

    def attach_link(self, receive: Receiver, sent: Callable[[], int], name: str) -> Callable[[], None]:
        """Returns the function that detaches it again."""

    def close(self) -> None: ...


class _ClockBase:
    """What both clocks derive from ``now`` and ``sleep_until``."""

    def sleep(self, seconds: float) -> None:
        self.sleep_until(self.now() + max(0.0, float(seconds)))

    def wait_for(self, predicate: Callable[[], bool], timeout_s: float, period_s: float = 0.02) -> bool:
        """Poll ``predicate`` every ``period_s`` of this clock's time; False after ``timeout_s``."""
        deadline = self.now() + timeout_s
        slept_to_deadline = False
        while True:
            if predicate():
                return True
            # Once slept to the deadline, it has passed: a lockstep vehicle may stop a step short of it (its
            # physics step, or the microsecond the release travels in), and asking again would never end.
            if slept_to_deadline or self.now() >= deadline:
                return False
            wake = min(deadline, self.now() + period_s)
            slept_to_deadline = wake >= deadline
            self.sleep_until(wake)


class WallClock(_ClockBase):
    """Real time: ``time.monotonic`` and ``time.sleep``; receivers run in threads of their own."""

    name = "wall"

    def __init__(self) -> None:
        self._closed = threading.Event()
        self._stops: dict[threading.Thread, threading.Event] = {}   # a spawned thread's waits end on stop()

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, t: float) -> None:
        delay = t - time.monotonic()
        if delay > 0:
            self._stops.get(threading.current_thread(), self._closed).wait(delay)

    def spawn(self, target: Callable[[ClockThread], None], name: str) -> ClockThread:
        handle = ClockThread(self, target, name)
        self._stops[handle.thread] = handle.stopped
        handle.thread.start()
        return handle

    def attach_link(self, receive: Receiver, sent: Callable[[], int], name: str) -> Callable[[], None]:
        stop = threading.Event()

        def loop() -> None:
            while not (stop.is_set() or self._closed.is_set()):
                receive(0.1)

        thread = threading.Thread(target=loop, name=name, daemon=True)
        thread.start()

        def detach() -> None:
            stop.set()
            thread.join(timeout=2)
        return detach

    def close(self) -> None:
        self._closed.set()

    def _thread_ended(self) -> None:
        pass

    def _thread_stopped(self, thread: threading.Thread) -> None:
        pass


class LockstepError(RuntimeError):
    """The vehicle stopped answering the lockstep side channel."""


class LockstepTransport(Protocol):
    """The clock's side of the side channel (see :class:`companion.lockstep.LockstepChannel`)."""

    def advance(self, until_s: float, sent_messages: int) -> tuple[float, int]:
        """Release the vehicle up to ``until_s``; block until it says it got there.  ``sent_messages`` is
        how many API messages this companion has sent so far (the vehicle reads them all first); returns
        (simulation time reached, API messages the vehicle has sent so far)."""

    def start(self) -> tuple[float, int]:
        """Wait for the held vehicle's first word: (its simulation time, API messages it has sent)."""


class _Waiter:
    __slots__ = ("order", "wake_s", "waiting", "stopped")

    def __init__(self, order: int) -> None:
        self.order = order
        self.wake_s = 0.0
        self.waiting = False
        self.stopped = False


class _Receiver:
    __slots__ = ("receive", "sent", "name", "taken")

    def __init__(self, receive: Receiver, sent: Callable[[], int], name: str, taken: int) -> None:
        self.receive, self.sent, self.name, self.taken = receive, sent, name, taken


class LockstepClock(_ClockBase):
    """The vehicle's simulation time, advanced by this companion (see the module docstring).

    ``transport`` talks to the vehicle.  Threads take part in the clock (their waits hold
    the vehicle) from their first wait, or from ``spawn``; the thread that creates the clock from the start;
    ``leave()`` ends it for the calling thread.  ``settle_s``: simulated time handed to the vehicle when the
    clock closes, so that it settles (in Hold, after a flight) before its verdict is taken; after that it
    stays held.  ``receive_timeout_s``: how long (wall time) a receiver may take to read the messages the
    vehicle sent before the clock goes on without them (a lost datagram: logged).
    """

    name = "lockstep"

    def __init__(self, transport: LockstepTransport, settle_s: float = 1.0, receive_timeout_s: float = 2.0) -> None:
        self._transport = transport
        self._cond = threading.Condition()
        self._waiters: dict[threading.Thread, _Waiter] = {}
        self._order = 0
        self._receivers: list[_Receiver] = []
        self._closed = False
        self._broken: str | None = None
        self.settle_s = float(settle_s)
        self.receive_timeout_s = float(receive_timeout_s)
        self.releases = 0
        self._now, self._vehicle_sent = transport.start()
        self._join(threading.current_thread())

    # ------------------------------------------------------------------------------ time
    def now(self) -> float:
        return self._now

    def sleep_until(self, t: float) -> None:
        with self._cond:
            me = self._waiters.get(threading.current_thread()) or self._join(threading.current_thread())
            if me.stopped or self._closed:
                return
            # to whole microseconds, as releases travel: sums of periods that differ by rounding wake together
            me.wake_s, me.waiting = max(round(float(t) * 1e6) / 1e6, self._now), True
            self._schedule()
            while me.waiting and not (me.stopped or self._closed or self._broken):
                self._cond.wait()
            me.waiting = False
            if self._broken:
                raise LockstepError(self._broken)

    # --------------------------------------------------------------------------- threads
    def spawn(self, target: Callable[[ClockThread], None], name: str) -> ClockThread:
        handle = ClockThread(self, target, name)
        with self._cond:
            self._join(handle.thread)
        handle.thread.start()
        return handle

    def leave(self) -> None:
        """The calling thread no longer takes part: its work no longer holds the vehicle."""
        self._thread_ended()

    def _join(self, thread: threading.Thread) -> _Waiter:
        waiter = self._waiters[thread] = _Waiter(self._order)
        self._order += 1
        return waiter

    def _thread_ended(self) -> None:
        with self._cond:
            self._waiters.pop(threading.current_thread(), None)
            self._schedule()

    def _thread_stopped(self, thread: threading.Thread) -> None:
        with self._cond:
            waiter = self._waiters.get(thread)
            if waiter is not None:
                waiter.stopped = True
            self._cond.notify_all()
            self._schedule()

    def attach_link(self, receive: Receiver, sent: Callable[[], int], name: str) -> Callable[[], None]:
        """After each release, ``receive`` is called until it has taken the messages the vehicle sent (counted
        from now: what the vehicle sent before the link existed never reached it); ``sent()`` is how many
        the link has sent, which the vehicle reads before it moves on."""
        receiver = _Receiver(receive, sent, name, self._vehicle_sent)
        with self._cond:
            self._receivers.append(receiver)

        def detach() -> None:
            with self._cond:
                if receiver in self._receivers:
                    self._receivers.remove(receiver)
        return detach

    # ------------------------------------------------------------------------- scheduling
    def _schedule(self) -> None:
        """With the lock held: if every participant waits, advance to the earliest wake-up and wake that one
        (ties in the order the participants joined)."""
        if self._closed or self._broken:
            self._cond.notify_all()
            return
        live = [w for t, w in self._waiters.items() if not w.stopped and (t.is_alive() or not t.ident)]
        if not live or any(not w.waiting for w in live):
            return
        nxt = min(live, key=lambda w: (w.wake_s, w.order))
        if nxt.wake_s > self._now:
            try:
                self._advance(nxt.wake_s)
            except (LockstepError, OSError) as exc:
                self._broken = str(exc)     # every waiter hears of it, not only this thread
                self._cond.notify_all()
                return
        nxt.waiting = False
        self._cond.notify_all()

    def _advance(self, until_s: float) -> None:
        sent = sum(r.sent() for r in self._receivers) % MESSAGE_COUNT_MODULUS
        self._now, self._vehicle_sent = self._transport.advance(until_s, sent)
        self.releases += 1
        for receiver in self._receivers:
            deadline = time.monotonic() + self.receive_timeout_s
            while _behind(receiver.taken, self._vehicle_sent):
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    log.warning("lockstep: %s is %d messages short of the vehicle's %d after %.1f s; going on "
                                "(a lost datagram: this flight may not repeat exactly)", receiver.name,
                                (self._vehicle_sent - receiver.taken) % MESSAGE_COUNT_MODULUS,
                                self._vehicle_sent, self.receive_timeout_s)
                    receiver.taken = self._vehicle_sent
                    break
                got = receiver.receive(min(0.005, remaining))
                receiver.taken = (receiver.taken + got) % MESSAGE_COUNT_MODULUS

    def close(self) -> None:
        """Hand the vehicle ``settle_s`` more seconds (see the class docstring), then end every wait."""
        with self._cond:
            if self._closed:
                return
            if not self._broken and self.settle_s > 0:
                try:
                    self._advance(self._now + self.settle_s)
                except (LockstepError, OSError) as exc:
                    log.warning("lockstep: the vehicle did not take its last %.1f s: %s", self.settle_s, exc)
            self._closed = True
            self._cond.notify_all()


MESSAGE_COUNT_MODULUS = 1 << 24   # counts travel as float32 (exact below 2**24) and wrap there


def _behind(taken: int, sent: int) -> bool:
    """Whether a receiver that took ``taken`` messages has not yet seen all ``sent`` (both mod 2**24)."""
    gap = (sent - taken) % MESSAGE_COUNT_MODULUS
    return 0 < gap < MESSAGE_COUNT_MODULUS // 2
