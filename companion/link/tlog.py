"""Writes a standard .tlog: each MAVLink packet preceded by its 8-byte big-endian microsecond UNIX time."""

from __future__ import annotations

import struct
import threading
import time
from pathlib import Path


class TlogWriter:
    """Thread-safe .tlog writer for both directions of a link (QGroundControl's and MAVProxy's format)."""

    def __init__(self, path: Path):
        path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(path, "wb")  # noqa: SIM115 — closed in close()
        self._lock = threading.Lock()
        self.packets = 0

    def write(self, packet: bytes, unix_time_s: float | None = None) -> None:
        stamp = int((time.time() if unix_time_s is None else unix_time_s) * 1e6)
        with self._lock:
            if self._file.closed:
                return
            self._file.write(struct.pack(">Q", stamp) + bytes(packet))
            self.packets += 1

    def close(self) -> None:
        with self._lock:
            self._file.close()
