"""Fuzzing the .ply reader (scenes.splats) with hypothesis: a damaged splat file is refused with one line.

Seeds: small real clouds written with ``write_ply`` (SH degrees 0, 1 and 3). Mutations: header lines removed,
duplicated, swapped or garbled, the vertex count changed (too big, negative, huge, not a number), the binary
body cut short or grown, header bytes flipped, NaN/inf written into properties.

Invariant: ``read_ply`` raises :class:`PlyError` (a ValueError) with a one-line message, or returns a cloud
that is exactly what a self-consistent file describes: finite everywhere, as many Gaussians as declared, the
body exactly as long as the header says. Never an IndexError, struct.error, UnicodeDecodeError, MemoryError,
and never a quietly wrong cloud. Budgets: support.fuzzing (docs/testing.md).
"""

from __future__ import annotations

import tracemalloc
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from scenes.splats import GaussianCloud, PlyError, read_ply, read_ply_header, write_ply  # noqa: E402
from support.fuzzing import fuzz_examples  # noqa: E402

pytestmark = pytest.mark.fuzz

END = b"end_header\n"
NORMALS = ("nx", "ny", "nz")  # in the 3DGS layout, but no Gaussian is drawn from them


def random_cloud(n: int, k: int, seed: int) -> GaussianCloud:
    rng = np.random.default_rng(seed)
    return GaussianCloud(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)) - 3.0, rng.normal(size=(n, 4)),
                         rng.normal(size=n), rng.normal(size=(n, k, 3)))


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> list[bytes]:
    directory = tmp_path_factory.mktemp("ply_seeds")
    out = []
    for n, k in ((6, 1), (4, 4), (3, 16)):  # SH degrees 0, 1, 3
        path = directory / f"seed_{n}_{k}.ply"
        write_ply(path, random_cloud(n, k, seed=n), write_labels=False)
        out.append(path.read_bytes())
    return out


def split(data: bytes) -> tuple[list[bytes], bytes]:
    end = data.index(END) + len(END)
    return data[:end].splitlines(keepends=True), data[end:]


def declared(lines: list[bytes]) -> tuple[int, list[str]]:
    """The seed's vertex count and property names, read here from its header lines (not by the reader)."""
    count = next(int(line.split()[2]) for line in lines if line.startswith(b"element vertex"))
    names = [line.split()[2].decode() for line in lines if line.startswith(b"property")]
    return count, names


@st.composite
def damaged_ply(draw, seeds: list[bytes]) -> bytes:
    lines, body = split(draw(st.sampled_from(seeds)))
    body = bytearray(body)
    for _ in range(draw(st.integers(1, 3))):
        kind = draw(st.sampled_from(["remove", "duplicate", "swap", "garble", "count", "cut", "grow", "flip",
                                     "nonfinite"]))
        if kind == "remove" and lines:
            del lines[draw(st.integers(0, len(lines) - 1))]
        elif kind == "duplicate" and lines:
            lines.insert(draw(st.integers(0, len(lines))), lines[draw(st.integers(0, len(lines) - 1))])
        elif kind == "swap" and len(lines) > 1:
            i = draw(st.integers(0, len(lines) - 2))
            lines[i], lines[i + 1] = lines[i + 1], lines[i]
        elif kind == "garble" and lines:
            lines[draw(st.integers(0, len(lines) - 1))] = draw(st.binary(max_size=40)) + b"\n"
        elif kind == "count":
            lines = [b"element vertex %s\n" % draw(vertex_counts()) if line.startswith(b"element vertex")
                     else line for line in lines]
        elif kind == "cut":
            del body[draw(st.integers(0, len(body))):]
        elif kind == "grow":
            body += draw(st.binary(min_size=1, max_size=64))
        elif kind == "flip" and lines:
            header = bytearray(b"".join(lines))
            header[draw(st.integers(0, len(header) - 1))] ^= draw(st.integers(1, 255))
            lines = [bytes(header)]
        elif kind == "nonfinite" and len(body) >= 4:
            at = 4 * draw(st.integers(0, len(body) // 4 - 1))
            body[at:at + 4] = np.array([draw(st.sampled_from([np.nan, np.inf, -np.inf]))], "<f4").tobytes()
    return b"".join(lines) + bytes(body)


def vertex_counts():
    return st.one_of(st.integers(-5, 50).map(lambda c: str(c).encode()),
                     st.sampled_from([b"2147483648", b"4611686018427387904", b"99999999999999999999999", b"1e3",
                                      b"0x10", b"+3", b"", b"7 7", "\u0663".encode(), b"3.0"]))


def drawn_group(name: str) -> str:
    """What the reader's message calls the part of a Gaussian a 3DGS property belongs to."""
    if name in ("x", "y", "z"):
        return "positions"
    if name == "opacity":
        return "opacities"
    return {"scale": "scales", "rot": "rotations", "f": "colours"}[name.split("_")[0]]


def one_line(exc: PlyError) -> str:
    text = str(exc)
    assert text and "\n" not in text, repr(text)
    return text


def assert_refused_or_consistent(path: Path, data: bytes) -> GaussianCloud | None:
    path.write_bytes(data)
    try:
        cloud = read_ply(path)
    except PlyError as exc:
        one_line(exc)
        return None
    n, props, offset, _ = read_ply_header(path)
    assert len(cloud) == n
    assert offset + n * np.dtype(props).itemsize == len(data), "accepted a body the header does not describe"
    for array in (cloud.means, cloud.log_scales, cloud.quats, cloud.opacity_logits, cloud.sh):
        assert np.isfinite(array).all(), "accepted NaN or inf"
    return cloud


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    """One file the examples overwrite in turn (module-scoped: hypothesis runs many examples per test call)."""
    return tmp_path_factory.mktemp("ply_fuzz") / "damaged.ply"


def read_ply_at(path: Path, data: bytes) -> GaussianCloud:
    path.write_bytes(data)
    return read_ply(path)


def refused_in_one_line(path: Path, data: bytes, match: str | None = None) -> str:
    with pytest.raises(PlyError, match=match) as refused:
        read_ply_at(path, data)
    return one_line(refused.value)


# ----------------------------------------------------------------------------------------------- generic
@settings(max_examples=fuzz_examples(200))
@given(draw=st.data())
def test_damaged_ply_files_are_refused_in_one_line_or_read_as_they_say(seeds, work, draw):
    assert_refused_or_consistent(work, draw.draw(damaged_ply(seeds), label="damaged file"))


# ------------------------------------------------------------------------------- each damage on its own
@settings(max_examples=fuzz_examples(60))
@given(seed=st.integers(0, 2), count=vertex_counts())
def test_any_other_vertex_count_is_refused(seeds, work, seed, count):
    lines, body = split(seeds[seed])
    if count == str(declared(lines)[0]).encode():
        return
    lines = [b"element vertex %s\n" % count if line.startswith(b"element vertex") else line for line in lines]
    refused_in_one_line(work, b"".join(lines) + body)


@pytest.mark.parametrize("count", [2**31, 2**40, 2**62, 10**30])
def test_a_huge_vertex_count_is_refused_before_anything_is_allocated(seeds, tmp_path, count):
    """Found by the fuzzing: 2**31 Gaussians made read_ply ask for 128 GB (MemoryError); 10**20 raised an
    OverflowError from the file read."""
    lines, body = split(seeds[0])
    lines = [b"element vertex %d\n" % count if line.startswith(b"element vertex") else line for line in lines]
    tracemalloc.start()
    try:
        text = refused_in_one_line(tmp_path / "huge.ply", b"".join(lines) + body, match="truncated")
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 1 << 20, f"{peak} bytes allocated to refuse it"
    assert str(count) in text


@settings(max_examples=fuzz_examples(60))
@given(seed=st.integers(0, 2), which=st.integers(0, 10**6), twice=st.booleans())
def test_a_property_line_lost_or_written_twice_is_refused(seeds, work, seed, which, twice):
    """Found by the fuzzing: without a property line every later column shifts by one and the reader, which
    did not compare the body with the header, returned a wrong cloud of finite numbers."""
    lines, body = split(seeds[seed])
    properties = [i for i, line in enumerate(lines) if line.startswith(b"property")]
    at = properties[which % len(properties)]
    if twice:
        lines.insert(at, lines[at])
    else:
        del lines[at]
    refused_in_one_line(work, b"".join(lines) + body)


@settings(max_examples=fuzz_examples(60))
@given(seed=st.integers(0, 2), cut=st.integers(1, 10**6), extra=st.binary(max_size=64))
def test_a_body_cut_short_or_grown_is_refused(seeds, work, seed, cut, extra):
    lines, body = split(seeds[seed])
    body = body[:len(body) - 1 - cut % len(body)] if not extra else body + extra
    refused_in_one_line(work, b"".join(lines) + body, match="truncated" if not extra else "more than the header")


@settings(max_examples=fuzz_examples(80))
@given(seed=st.integers(0, 2), row=st.integers(0, 10**6), column=st.integers(0, 10**6),
       value=st.sampled_from([np.nan, np.inf, -np.inf]))
def test_nan_or_inf_in_a_drawn_property_is_refused_and_named(seeds, work, seed, row, column, value):
    """Found by the fuzzing: NaN or inf in an opacity, a rotation or a colour was accepted (only positions and
    scales were checked); the renderer turns one into a black or garbage frame."""
    lines, body = split(seeds[seed])
    n, names = declared(lines)
    row, column = row % n, column % len(names)
    values = np.frombuffer(body, "<f4").reshape(n, len(names)).copy()
    values[row, column] = value
    damaged = b"".join(lines) + values.tobytes()
    if names[column] in NORMALS:  # not drawn from: the cloud is the same as without the damage
        assert assert_refused_or_consistent(work, damaged) is not None
        return
    text = refused_in_one_line(work, damaged, match="non-finite")
    assert drawn_group(names[column]) in text and f"index {row}" in text


@pytest.fixture(scope="module")
def originals(seeds, tmp_path_factory) -> list[GaussianCloud]:
    return [read_ply_at(tmp_path_factory.mktemp("ply_orig") / "seed.ply", data) for data in seeds]


@settings(max_examples=fuzz_examples(120))
@given(seed=st.integers(0, 2), at=st.integers(0, 10**6), mask=st.integers(1, 255))
def test_header_bytes_flipped_are_refused_or_read_the_same(seeds, originals, work, seed, at, mask):
    lines, body = split(seeds[seed])
    header = bytearray(b"".join(lines))
    header[at % len(header)] ^= mask
    cloud = assert_refused_or_consistent(work, bytes(header) + body)
    if cloud is not None:  # a flip the reader accepts may only touch what it does not use (nx → ox, "1.0" → "1.1")
        original = originals[seed]
        assert len(cloud) == len(original)
        for ours, theirs in ((cloud.means, original.means), (cloud.sh, original.sh), (cloud.quats, original.quats),
                             (cloud.log_scales, original.log_scales),
                             (cloud.opacity_logits, original.opacity_logits)):
            assert np.array_equal(ours, theirs), "a header flip was read as a different cloud"
