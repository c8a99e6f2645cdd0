"""The companion's MAVLink 2 signing key: PX4's key file, read as the autopilot's end reads it.

A PX4 key file is 40 bytes: the 32-byte secret key, then the 64-bit little-endian timestamp (10 µs since
2015-01-01 UTC), mode 0600.  The companion signs everything it sends with the secret (pymavlink's
``setup_signing``), starting from the later of the file's timestamp and the wall clock, and accepts from the
autopilot only correctly signed messages (and the unsigned HEARTBEAT, RADIO_STATUS, ADSB_VEHICLE and
COLLISION that PX4 also lets through).  The simulated vehicle (``flowgap-vehicle --signing-key``) reads the
same file; the two packages share the format, not code.
"""

from __future__ import annotations

import stat
import struct
import time
from dataclasses import dataclass
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

KEY_FILE_LENGTH = 40
EPOCH_2015_UNIX_S = 1_420_070_400
ALLOWED_UNSIGNED = frozenset({mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_RADIO_STATUS,
                              mavlink.MAVLINK_MSG_ID_ADSB_VEHICLE, mavlink.MAVLINK_MSG_ID_COLLISION})


class SigningKeyError(ValueError):
    """A key file that cannot be used; one line: the file, the problem, the fix."""


@dataclass(frozen=True)
class CompanionKey:
    secret: bytes
    timestamp: int

    def initial_timestamp(self, unix_s: float | None = None) -> int:
        """Where the companion's signing clock starts: never behind the file nor the wall clock."""
        unix_s = time.time() if unix_s is None else unix_s
        return max(self.timestamp, int((unix_s - EPOCH_2015_UNIX_S) * 100_000))


def load_key(path: str | Path) -> CompanionKey:
    path = Path(path)
    try:
        info = path.stat()
        data = path.read_bytes() if stat.S_ISREG(info.st_mode) else b""
    except FileNotFoundError:
        raise SigningKeyError(f"signing key file {path} does not exist (make one with flowgap-vehicle "
                              f"--new-signing-key {path})") from None
    except OSError as exc:
        raise SigningKeyError(f"signing key file {path}: {exc.strerror}") from None
    if stat.S_IMODE(info.st_mode) & 0o077:
        raise SigningKeyError(f"signing key file {path} is mode {stat.S_IMODE(info.st_mode):04o}, readable by "
                              f"others: chmod 600 {path}")
    if len(data) != KEY_FILE_LENGTH:
        raise SigningKeyError(f"signing key file {path} is {len(data)} bytes; a PX4 key file is 40: 32 bytes of "
                              f"secret key, then an 8-byte little-endian timestamp")
    secret, (timestamp,) = data[:32], struct.unpack("<Q", data[32:])
    if not any(secret) and timestamp == 0:
        raise SigningKeyError(f"signing key file {path} is blank (all zeros: signing off); give the file that "
                              f"holds the vehicle's key")
    return CompanionKey(secret, timestamp)


def accept_unsigned(_mav, msg_id: int) -> bool:
    """pymavlink's callback for messages without a valid signature: PX4's allowlist only."""
    return msg_id in ALLOWED_UNSIGNED
