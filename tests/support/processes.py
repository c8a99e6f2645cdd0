"""Processes as Linux's /proc shows them, for tests that check what a command leaves running."""

from __future__ import annotations

from pathlib import Path


def proc_stat(pid: int | str) -> list[str] | None:
    """A process's /proc stat fields after its name (state, parent, group, session, ...), None once it is gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return text[text.rindex(")") + 2:].split()


def pids() -> list[int]:
    """Every process's id."""
    return [int(p.name) for p in Path("/proc").glob("[0-9]*")]


def alive(candidates) -> set[int]:
    """Those of ``candidates`` still running (a zombie is not)."""
    return {int(pid) for pid in candidates if (stat := proc_stat(pid)) is not None and stat[0] != "Z"}


def children(parent: int) -> set[int]:
    """The live processes whose parent is ``parent``."""
    return alive(pid for pid in pids() if (stat := proc_stat(pid)) and int(stat[1]) == parent)
