"""The companion's clocks: the wall clock, and the lockstep clock's scheduling against a scripted vehicle."""

from __future__ import annotations

import threading
import time

import pytest

from companion.clock import LockstepClock, LockstepError, WallClock


class ScriptedVehicle:
    """A lockstep transport that reaches exactly what it is released to, records every release, and can send
    API messages during each advance (``outbox``: messages to 'send' per advance)."""

    def __init__(self, start_s: float = 0.0, fail_after: int | None = None) -> None:
        self.now = start_s
        self.releases: list[tuple[float, int]] = []
        self.sent = 0
        self.per_advance = 0
        self.fail_after = fail_after

    def start(self):
        return self.now, self.sent

    def advance(self, until_s, sent_messages):
        if self.fail_after is not None and len(self.releases) >= self.fail_after:
            raise LockstepError("the vehicle stopped answering")
        self.releases.append((until_s, sent_messages))
        self.now = until_s
        self.sent += self.per_advance
        return self.now, self.sent


def test_wall_clock_sleeps_in_real_time_and_a_stopped_thread_wakes_at_once():
    clock = WallClock()
    t0 = clock.now()
    clock.sleep(0.05)
    assert 0.045 <= clock.now() - t0 < 1.0
    woke = []
    handle = clock.spawn(lambda me: (clock.sleep(30.0), woke.append(me.stopped.is_set())), "sleeper")
    time.sleep(0.05)
    handle.stop()
    handle.join(timeout=2)
    assert woke == [True]


def test_lockstep_time_moves_only_by_releases_and_sleeps_end_exactly_at_their_time():
    vehicle = ScriptedVehicle(start_s=3.0)
    clock = LockstepClock(vehicle, settle_s=0.0)
    assert clock.now() == 3.0
    time.sleep(0.05)                         # wall time passing moves nothing
    assert clock.now() == 3.0 and vehicle.releases == []
    clock.sleep(0.25)
    assert clock.now() == pytest.approx(3.25) and [r[0] for r in vehicle.releases] == [pytest.approx(3.25)]
    assert clock.wait_for(lambda: False, 0.1, 0.02) is False
    assert clock.now() == pytest.approx(3.35)
    assert len(vehicle.releases) == 6        # 0.1 s of polling every 0.02 s: five more releases


def test_lockstep_holds_the_vehicle_while_any_participant_works_and_wakes_them_in_a_fixed_order():
    vehicle = ScriptedVehicle()
    clock = LockstepClock(vehicle, settle_s=0.0)
    log: list[tuple[str, float]] = []

    def ticker(me):                          # a 20 Hz stream, like the link's setpoint thread
        t = clock.now()
        while not me.stopped.is_set() and t < 0.3:
            log.append(("tick", clock.now()))
            t += 0.05
            clock.sleep_until(t)

    handle = clock.spawn(ticker, "ticker")
    for _ in range(3):
        time.sleep(0.05)                     # "perception": real time passes, simulated time must not
        log.append(("work", clock.now()))
        clock.sleep(0.1)
    handle.stop()
    handle.join(timeout=2)
    releases = [round(r[0], 3) for r in vehicle.releases]
    assert releases == sorted(releases) and len(set(releases)) == len(releases)
    # Every 'work' happened with time held where the previous sleep ended; ticks kept their 50 ms grid; at a
    # tie (0.1, 0.2) the thread that joined the clock first (the creating one) goes first.
    works = [t for kind, t in log if kind == "work"]
    assert works == pytest.approx([0.0, 0.1, 0.2])
    ticks = [t for kind, t in log if kind == "tick"]
    assert ticks == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2, 0.25][:len(ticks)]) and len(ticks) >= 5
    assert [k for k, t in log if abs(t - 0.1) < 1e-9] == ["work", "tick"]


def test_the_same_program_on_the_lockstep_clock_gives_the_same_trace_however_slow_its_work():
    def trace(work_s: float) -> list:
        vehicle = ScriptedVehicle()
        clock = LockstepClock(vehicle, settle_s=0.0)
        out = []

        def stream(me):
            while not me.stopped.is_set() and clock.now() < 1.0:
                out.append(("s", round(clock.now(), 6)))
                clock.sleep(0.05)

        handle = clock.spawn(stream, "stream")
        while clock.now() < 1.0:
            time.sleep(work_s)
            out.append(("m", round(clock.now(), 6)))
            clock.sleep(0.07)
        handle.stop()
        handle.join(timeout=2)
        return out, [round(r[0], 6) for r in vehicle.releases]

    assert trace(0.0) == trace(0.01)


def test_a_receiver_is_called_until_it_has_the_messages_the_vehicle_sent_and_the_vehicle_gets_the_count():
    vehicle = ScriptedVehicle()
    vehicle.per_advance = 3
    clock = LockstepClock(vehicle, settle_s=0.0)
    inbox: list[int] = []
    arrivals = iter([0, 1, 0, 2] * 10)       # the messages trickle in over several reads

    def receive(timeout_s):
        n = next(arrivals)
        inbox.extend([1] * n)
        return n

    sent = [7]
    detach = clock.attach_link(receive, lambda: sent[0], "link")
    clock.sleep(0.02)
    assert len(inbox) == 3 and vehicle.releases[-1][1] == 7
    sent[0] = 9
    clock.sleep(0.02)
    assert len(inbox) == 6 and vehicle.releases[-1][1] == 9
    detach()
    clock.sleep(0.02)
    assert len(inbox) == 6


def test_a_lost_message_costs_a_warning_not_a_hang(caplog):
    vehicle = ScriptedVehicle()
    vehicle.per_advance = 2
    clock = LockstepClock(vehicle, settle_s=0.0, receive_timeout_s=0.1)
    clock.attach_link(lambda timeout_s: 0, lambda: 0, "link")
    t0 = time.monotonic()
    clock.sleep(0.02)
    assert time.monotonic() - t0 < 2.0 and "2 messages short" in caplog.text


def test_a_vehicle_that_stops_answering_fails_every_waiting_thread():
    clock = LockstepClock(ScriptedVehicle(fail_after=2), settle_s=0.0)
    errors = []

    def sleeper(me):
        try:
            clock.sleep(10.0)
        except LockstepError as exc:
            errors.append(str(exc))

    handle = clock.spawn(sleeper, "sleeper")
    with pytest.raises(LockstepError, match="stopped answering"):
        for _ in range(5):
            clock.sleep(0.01)
    handle.join(timeout=2)
    assert errors and "stopped answering" in errors[0]


def test_closing_hands_the_vehicle_its_settling_time_and_ends_every_wait():
    vehicle = ScriptedVehicle()
    clock = LockstepClock(vehicle, settle_s=1.0)
    clock.sleep(0.5)
    done = threading.Event()

    def waiter(me):
        clock.sleep(100.0)
        done.set()

    clock.spawn(waiter, "waiter")
    time.sleep(0.05)     # this thread works, so the waiter's 100 s cannot pass ...
    assert not done.is_set() and vehicle.releases[-1][0] == pytest.approx(0.5)
    clock.close()        # ... until the clock closes: one last second for the vehicle, then every wait ends
    assert done.wait(2)
    assert [r[0] for r in vehicle.releases][-1] == pytest.approx(1.5)


class SteppingVehicle(ScriptedVehicle):
    """Reaches the last 4 ms physics step at or before a release (as the vehicle does within half a step), and
    reports it in whole microseconds read back as the side channel reads them (``time_usec * 1e-6``)."""

    def advance(self, until_s, sent_messages):
        self.releases.append((until_s, sent_messages))
        steps = int((until_s - self.now) / 0.004 + 0.5)
        self.now = round((self.now + steps * 0.004) * 1e6) * 1e-6
        return self.now, self.sent


@pytest.mark.parametrize("timeout_s", [3.0, 3.001])    # 3.2 s: 3200000 * 1e-6 < 3.2; 3.201 s: a step short
def test_a_wait_that_times_out_ends_even_when_the_vehicle_stops_short_of_its_deadline(timeout_s):
    vehicle = SteppingVehicle(start_s=0.2)
    clock = LockstepClock(vehicle, settle_s=0.0)
    result = []
    waiter = threading.Thread(target=lambda: result.append(clock.wait_for(lambda: False, timeout_s, 0.005)),
                              daemon=True)
    clock.leave()                     # only the waiter takes part
    waiter.start()
    waiter.join(timeout=10)
    assert result == [False] and len(vehicle.releases) <= 752
