"""The scene cache's size limit: least recently used scenes go first.

A built scene is four files in the cache folder: ``NAME.ply``, ``NAME.ply.labels.npy``, ``NAME.json`` and
``NAME.key``. The key file's modification time is the scene's last use (:func:`touch` on every hit), so a sweep of
hundreds of random scenes (15-25 MB each) keeps the cache within ``$FLOWGAP_SCENE_CACHE_MB`` instead of filling the
disk. A scene used within the last :data:`RECENT_USE_S` is never removed: another flight of the same sweep may be
about to read it.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import time
from pathlib import Path

from scenes.spec import SpecError

log = logging.getLogger(__name__)

DEFAULT_LIMIT_MB = 5000
LIMIT_ENV = "FLOWGAP_SCENE_CACHE_MB"
RECENT_USE_S = 900.0
SCENE_SUFFIXES = (".ply", ".ply.labels.npy", ".json", ".key")


@dataclasses.dataclass(frozen=True)
class CacheEntry:
    """One built scene in the cache: its name, files, bytes on disk and last use (epoch seconds)."""

    name: str
    files: tuple[Path, ...]
    bytes: int
    last_used: float


def limit_bytes(env: dict[str, str] | None = None) -> int | None:
    """The cache's limit from ``$FLOWGAP_SCENE_CACHE_MB`` (default 5000 MB); None when it is 0 (no limit)."""
    raw = (os.environ if env is None else env).get(LIMIT_ENV, "").strip()
    if not raw:
        return DEFAULT_LIMIT_MB * 1_000_000
    try:
        mb = float(raw)
    except ValueError:
        mb = float("nan")
    if not (math.isfinite(mb) and mb >= 0):
        raise SpecError(f"${LIMIT_ENV}={raw!r} is not a size in MB; set a number such as 5000, or 0 for no limit")
    return None if mb == 0 else int(mb * 1_000_000)


def touch(key_file: Path) -> None:
    """Mark a cached scene as used now (a read-only cache is left as it is)."""
    try:
        os.utime(key_file)
    except OSError:
        pass


def entries(cache_dir: Path) -> list[CacheEntry]:
    """The built scenes in ``cache_dir``, least recently used first (a scene is known by its ``.key`` file)."""
    found = []
    for key in Path(cache_dir).glob("*.key"):
        name = key.name[:-len(".key")]
        files, size, last_used = [], 0, None
        for suffix in SCENE_SUFFIXES:
            path = key.with_name(name + suffix)
            try:
                st = path.stat()
            except FileNotFoundError:
                continue
            files.append(path)
            size += st.st_size
            if suffix == ".key":
                last_used = st.st_mtime
        if last_used is not None:        # removed by another process while we looked
            found.append(CacheEntry(name, tuple(files), size, last_used))
    return sorted(found, key=lambda e: (e.last_used, e.name))


def prune(cache_dir: Path, max_bytes: int | None, keep: tuple[str, ...] = (), recent_s: float = RECENT_USE_S,
          now: float | None = None) -> list[CacheEntry]:
    """Remove least recently used scenes until the cache holds at most ``max_bytes``; returns those removed.

    Scenes named in ``keep`` and those used within ``recent_s`` seconds of ``now`` stay, even if the cache is then
    still over its limit. ``max_bytes`` None means no limit."""
    if max_bytes is None:
        return []
    now = time.time() if now is None else now
    listed = entries(cache_dir)
    total = sum(e.bytes for e in listed)
    removed = []
    for entry in listed:
        if total <= max_bytes:
            break
        if entry.name in keep or now - entry.last_used < recent_s:
            continue
        for path in sorted(entry.files, key=lambda f: f.suffix != ".key"):   # the key first: at once "not built"
            path.unlink(missing_ok=True)
        total -= entry.bytes
        removed.append(entry)
    if removed:
        log.info("scene cache %s: removed %d least recently used scenes (%.0f MB) to stay within %.0f MB",
                 cache_dir, len(removed), sum(e.bytes for e in removed) / 1e6, max_bytes / 1e6)
    return removed
