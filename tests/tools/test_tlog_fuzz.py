"""Fuzzing the tlog reader (tools.tlog) with hypothesis: damaged logs are analysed or noted, never a traceback.

Two real logs are the seeds: the start of a third-party ArduSub log (tests/data) and a flowgap-style PX4 flight
written with the companion's own TlogWriter. Mutations: truncation at any offset, byte flips, inserted
garbage, duplicated chunks, deleted spans, a zero-length file, files that are not tlogs at all.

Invariants: :func:`analyse_tlog` returns a report whose framing accounts for every byte of the file (packets +
skipped garbage + truncated tail = file size), whose notes are one line each, and in which no analysis stage
died on an exception it did not foresee; ``flowgap-tlog`` exits 0 or 1 with only its own one-line messages on
stderr, and 2 with one line for a file it cannot read. Budgets: support.fuzzing (docs/testing.md).
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from pymavlink.dialects.v20 import common as mav2  # noqa: E402

from companion.jsonsafe import json_safe  # noqa: E402
from companion.link.tlog import TlogWriter  # noqa: E402
from support.fuzzing import fuzz_examples  # noqa: E402
from tools.tlog import analyse_tlog, main, summary_text  # noqa: E402
from tools.tlog.framing import load_dialect, scan_tlog  # noqa: E402

pytestmark = pytest.mark.fuzz

ARDUSUB = Path(__file__).resolve().parents[1] / "data" / "ardusub-qgc-small.tlog"
T0_S = 1_750_000_000.0  # an arbitrary UNIX time
PX4_OFFBOARD = 6 << 16
ARMED = 128 | 1  # MAV_MODE_FLAG_SAFETY_ARMED | CUSTOM_MODE_ENABLED
SEED_BYTES = 24_000  # the ArduSub seed: its first records, enough for every message kind near the start


def flowgap_flight(path: Path) -> list[int]:
    """A short flowgap-style PX4 flight (heartbeats, offboard setpoints from the companion, the estimate, the
    ground-truth ODOMETRY, STATUSTEXT), written with the companion's TlogWriter; returns each record's size."""
    vehicle = mav2.MAVLink(None, srcSystem=1, srcComponent=1)
    companion = mav2.MAVLink(None, srcSystem=255, srcComponent=190)
    writer = TlogWriter(path)
    sizes = []

    def put(mav, t_s: float, msg) -> None:
        packet = msg.pack(mav)
        writer.write(packet, T0_S + t_s)
        sizes.append(8 + len(packet))

    for k in range(120):  # 6 s at 20 Hz
        t = k * 0.05
        if k % 20 == 0:
            put(vehicle, t, mav2.MAVLink_heartbeat_message(2, 12, ARMED, PX4_OFFBOARD, 4, 3))
        if k == 30:
            put(vehicle, t, mav2.MAVLink_statustext_message(6, b"Takeoff to 1.5 m above home"))
        x = 0.1 * t
        put(companion, t, mav2.MAVLink_set_position_target_local_ned_message(
            int(t * 1e3), 1, 1, 1, 0x0FF8, x + 0.05, 0.0, -1.5, 0, 0, 0, 0, 0, 0, 0, 0))
        put(vehicle, t + 0.01, mav2.MAVLink_local_position_ned_message(int(t * 1e3), x, 0.01, -1.5, 0.1, 0, 0))
        put(vehicle, t + 0.02, mav2.MAVLink_odometry_message(
            int(t * 1e6), 1, 12, x, 0.0, -1.5, [1, 0, 0, 0], 0.1, 0, 0, 0, 0, 0, [float("nan")] * 21,
            [float("nan")] * 21, 0, 6, 100))
    writer.close()
    return sizes


@pytest.fixture(scope="module")
def flowgap_sizes(seeds) -> list[int]:
    return seeds["flowgap_sizes"]


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> dict:
    directory = tmp_path_factory.mktemp("tlog_seeds")
    flowgap = directory / "flowgap.tlog"
    sizes = flowgap_flight(flowgap)
    raw = ARDUSUB.read_bytes()
    frames = scan_tlog(raw, load_dialect())
    ends = [int(r + s) for r, s in zip(frames.rec, frames.size, strict=True)]
    cut = max(e for e in ends if e <= SEED_BYTES)  # end on a record boundary: the seed itself is whole
    return {"ardusub": raw[:cut], "flowgap": flowgap.read_bytes(), "flowgap_sizes": sizes}


@st.composite
def damaged(draw, seed: bytes) -> bytes:
    """``seed`` with one to four damages of the kinds a log meets: cut short, bits flipped on disk or on the
    wire, garbage written into it, a chunk written twice, a span lost."""
    data = bytearray(seed)
    for _ in range(draw(st.integers(1, 4))):
        n = len(data)
        if n == 0:
            break
        kind = draw(st.sampled_from(["truncate", "flip", "insert", "duplicate", "delete"]))
        if kind == "truncate":
            del data[draw(st.integers(0, n)):]
        elif kind == "flip":
            for _ in range(draw(st.integers(1, 16))):
                data[draw(st.integers(0, n - 1))] ^= draw(st.integers(1, 255))
        elif kind == "insert":
            at = draw(st.integers(0, n))
            data[at:at] = draw(st.binary(min_size=1, max_size=300))
        elif kind == "duplicate":
            start = draw(st.integers(0, n - 1))
            chunk = data[start:start + draw(st.integers(1, 2000))]
            at = draw(st.integers(0, n))
            data[at:at] = chunk
        else:
            start = draw(st.integers(0, n - 1))
            del data[start:start + draw(st.integers(1, 500))]
    return bytes(data)


def assert_analysed_or_noted(path: Path, size: int):
    rep = analyse_tlog(path)
    for note in rep.notes:
        assert "\n" not in note, note
        assert "analysis failed" not in note, f"a stage died on an unforeseen exception: {note}"
    framing = rep.metrics["framing"]
    if rep.frames is not None:
        accounted = int(rep.frames.size.sum()) + rep.frames.garbage_bytes + rep.frames.trailing_bytes
        assert accounted == size, f"{accounted} bytes accounted for in a {size}-byte file"
        if rep.usable:
            assert framing["packets"] == len(rep.frames)
            assert framing["garbage_bytes"] == rep.frames.garbage_bytes
            assert framing["truncated_tail_bytes"] == rep.frames.trailing_bytes
    if not rep.usable:
        assert rep.notes, "an unusable log without a note saying why"
    summary_text(rep)
    json.dumps(json_safe(rep.to_json()))
    return rep


def run_cli(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(args))
    return code, out.getvalue(), err.getvalue()


# -------------------------------------------------------------------------------------------- analysis
@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """One file the examples overwrite in turn (module-scoped: hypothesis runs many examples per test call)."""
    return tmp_path_factory.mktemp("tlog_fuzz") / "damaged.tlog"


def analyse_tlog_bytes(path: Path, data: bytes):
    path.write_bytes(data)
    return assert_analysed_or_noted(path, len(data))


@pytest.mark.parametrize("seed_name", ["ardusub", "flowgap"])
def test_the_seeds_are_whole_logs(seeds, seed_name, work):
    rep = analyse_tlog_bytes(work, seeds[seed_name])
    assert rep.usable and rep.frames.garbage_bytes == 0 and rep.frames.trailing_bytes == 0


@pytest.mark.parametrize("seed_name", ["ardusub", "flowgap"])
@settings(max_examples=fuzz_examples(100))
@given(draw=st.data())
def test_damaged_logs_are_analysed_with_every_byte_accounted_for(seeds, seed_name, work, draw):
    analyse_tlog_bytes(work, draw.draw(damaged(seeds[seed_name]), label="damaged log"))


@settings(max_examples=fuzz_examples(80))
@given(draw=st.data())
def test_a_cut_anywhere_keeps_the_whole_records_and_reports_the_rest_as_a_truncated_tail(seeds, flowgap_sizes,
                                                                                         work, draw):
    seed = seeds["flowgap"]
    cut = draw.draw(st.integers(1, len(seed) - 1), label="cut")
    rep = analyse_tlog_bytes(work, seed[:cut])
    ends = np.cumsum(flowgap_sizes)  # the writer's own record sizes: no reader involved
    whole = ends[ends <= cut]
    if not whole.size:  # cut inside the first record: nothing to analyse, and a note says so
        assert not rep.usable
        return
    tail = cut - int(whole[-1])
    assert len(rep.frames) == whole.size and rep.frames.garbage_bytes == 0
    assert rep.frames.trailing_bytes == tail
    assert any("truncated" in note for note in rep.notes) == (tail > 0)


@settings(max_examples=fuzz_examples(80))
@given(draw=st.data(), garbage=st.binary(min_size=1, max_size=300))
def test_garbage_between_records_is_skipped_and_counted(seeds, flowgap_sizes, work, draw, garbage):
    seed = seeds["flowgap"]
    at = int(draw.draw(st.sampled_from(np.cumsum(flowgap_sizes)[:-1].tolist()), label="between records at"))
    rep = analyse_tlog_bytes(work, seed[:at] + garbage + seed[at:])
    assert len(rep.frames) == len(flowgap_sizes), "a record was lost to (or made up from) the garbage"
    assert rep.frames.garbage_bytes == len(garbage) and rep.frames.garbage_runs == 1
    assert rep.metrics["messages"]["total"] == len(flowgap_sizes)


@pytest.mark.parametrize("into", range(1, 9))
def test_a_log_cut_inside_a_timestamp_ends_with_a_truncated_tail(seeds, flowgap_sizes, work, into):
    """Found by the fuzzing: a cut that left 1-8 bytes of the last record's timestamp was reported as that
    many bytes of "non-MAVLink data" rather than as a truncated log."""
    boundary = sum(flowgap_sizes[:10])
    rep = analyse_tlog_bytes(work, seeds["flowgap"][:boundary + into])
    assert len(rep.frames) == 10 and rep.frames.garbage_bytes == 0 and rep.frames.trailing_bytes == into
    assert any("truncated" in note for note in rep.notes) and not any("non-MAVLink" in n for n in rep.notes)


def test_a_corrupt_first_timestamp_is_skipped_not_taken_as_the_start(seeds, flowgap_sizes, work):
    """Found by the fuzzing: one flipped bit in the first record's time made it the log's start, hundreds of
    years from the rest; the summary stage died on the date ("year -290254 is out of range")."""
    for bit in (0x80, 0x01, 0x10):
        data = bytearray(seeds["flowgap"])
        data[0] ^= bit
        rep = analyse_tlog_bytes(work, bytes(data))
        assert rep.metrics["start_utc"].startswith("2025-06-15")  # T0_S, the flight's real start
        assert rep.frames.garbage_bytes == flowgap_sizes[0] and len(rep.frames) == len(flowgap_sizes) - 1


def test_a_log_whose_only_times_are_not_unix_times_says_so(seeds, flowgap_sizes, work):
    one = bytearray(seeds["flowgap"][:flowgap_sizes[0]])
    one[0] = 0xFF  # ≥ 2**63 µs: no date at all
    rep = analyse_tlog_bytes(work, bytes(one))
    assert rep.usable and rep.metrics["start_utc"] is None
    assert any("not a UNIX time" in note for note in rep.notes)


# ------------------------------------------------------------------------------------------------- CLI
@settings(max_examples=fuzz_examples(30))
@given(draw=st.data())
def test_cli_on_damaged_logs_exits_0_or_1_with_one_line_messages(seeds, work, draw):
    seed = seeds[draw.draw(st.sampled_from(["ardusub", "flowgap"]), label="seed")]
    work.write_bytes(draw.draw(damaged(seed), label="damaged log"))
    code, out, err = run_cli(str(work), "--json", "-q")
    assert code in (0, 1), err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert all(line.startswith("flowgap-tlog: ") for line in lines), lines
    assert json.loads(out)["usable"] is (code == 0)
    if code == 1:
        assert lines, "exit 1 without a word"


@pytest.mark.parametrize("content, words", [
    (b"", "empty"),
    (b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 8, "not a tlog"),
    (b"timestamp,x,y,z\n" * 200, "not a tlog"),
])
def test_cli_on_files_that_are_not_tlogs_exits_1_with_one_line(tmp_path, content, words):
    path = tmp_path / "not.tlog"
    path.write_bytes(content)
    code, _, err = run_cli(str(path), "-q")
    assert code == 1 and len(err.splitlines()) == 1 and words in err


def test_cli_on_unreadable_input_exits_2_with_one_line(tmp_path, monkeypatch):
    """Found by these tests: a file the analysis could not read got two lines, its note and the CLI's error."""
    code, _, err = run_cli(str(tmp_path / "missing.tlog"))
    assert code == 2 and len(err.splitlines()) == 1 and "no such file" in err
    code, _, err = run_cli(str(tmp_path))
    assert code == 2 and len(err.splitlines()) == 1 and "not a file" in err
    locked = tmp_path / "locked.tlog"
    locked.write_bytes(b"x")
    real_open, real_read = Path.open, Path.read_bytes

    def refuse(self, *args, **kwargs):  # a permission error: tests may run as root, where chmod makes none
        if self == locked:
            raise PermissionError(13, "Permission denied", str(self))
        return real_open(self, *args, **kwargs)

    monkeypatch.setattr(Path, "open", refuse)
    code, _, err = run_cli(str(locked))
    assert code == 2 and err.splitlines() == [f"flowgap-tlog: error: cannot read {locked}: Permission denied"]
    # unreadable only by the time the analysis reads it: still one line
    monkeypatch.setattr(Path, "open", real_open)
    monkeypatch.setattr(Path, "read_bytes", lambda self: refuse(self) if self == locked else real_read(self))
    code, _, err = run_cli(str(locked))
    assert code == 2 and len(err.splitlines()) == 1 and "Permission denied" in err
