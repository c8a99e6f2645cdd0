"""Signing at the vehicle's link edge: every link signs what it sends, and what arrives passes the check.

:class:`LinkSigning` ties the pure :class:`~sitl_vehicle.signing.MessageVerifier` to the vehicle's UDP links
and to the key file (``flowgap-vehicle --signing-key FILE``).  It is what ``MavlinkVehicleInterface`` asks
whether a received message may be handled, and what handles SETUP_SIGNING.  Without a key file a key set by
SETUP_SIGNING lives for this run only (said in the log).  Rejected messages are counted by reason, logged and
answered with a STATUSTEXT at most every :data:`REJECT_REPORT_S` seconds per link.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

from sitl_vehicle import signing
from sitl_vehicle.signing import DISABLED, MessageVerifier, SigningKey, timestamp_from_unix

log = logging.getLogger(__name__)

REJECT_REPORT_S = 5.0        # one STATUSTEXT about rejected messages per link at most this often (wall s)
LOG_SUMMARY_EVERY = 100      # and a log line with the counts every this many rejections


class LinkSigning:
    """``key_path``: the PX4 key file (None: no file, signing off until a SETUP_SIGNING); ``unix_time``: the
    wall clock (for the signing clock's start and the report rate), injectable for tests."""

    def __init__(self, key_path: str | Path | None = None, unix_time=time.time) -> None:
        self.key_path = Path(key_path) if key_path is not None else None
        self.unix_time = unix_time
        self.verifier = MessageVerifier()
        self.links: list = []
        self._last_report: dict[str, float] = {}
        self._report: tuple | None = None
        key = signing.read_key_file(self.key_path) if self.key_path is not None else None
        self.verifier.set_key(key, timestamp_from_unix(unix_time()))
        if self.active:
            log.info("MAVLink signing on (key from %s): unsigned messages are dropped but HEARTBEAT, RADIO_STATUS, "
                     "ADSB_VEHICLE and COLLISION", self.key_path)

    @property
    def active(self) -> bool:
        return self.verifier.active

    def attach(self, link) -> None:
        """Sign what ``link`` sends (its link id is its place in the order links are attached)."""
        self.links.append(link)
        self._configure(link, len(self.links) - 1)

    def _configure(self, link, link_id: int) -> None:
        key = self.verifier.key
        link.sign_outgoing(key.secret if key is not None else None, link_id, lambda: self.verifier.timestamp)

    # ------------------------------------------------------------------------------------ incoming
    def admit(self, msg, link) -> bool:
        """Whether a received message may be handled; a rejection is counted, logged and reported."""
        frame = msg.get_msgbuf()
        outcome = self.verifier.check(frame, msg.get_msgId(), msg.get_srcSystem(), msg.get_srcComponent())
        if not signing.is_rejection(outcome):
            return True
        rejected = sum(v for k, v in self.verifier.counts.items() if signing.is_rejection(k))
        if rejected % LOG_SUMMARY_EVERY == 1:
            log.warning("signing: dropped %s from %d/%d on the %s link (%s); counts %s", msg.get_type(),
                        msg.get_srcSystem(), msg.get_srcComponent(), link.name, outcome.removeprefix("rejected_"),
                        self.verifier.summary())
        now = self.unix_time()
        if now - self._last_report.get(link.name, -float("inf")) >= REJECT_REPORT_S:
            self._last_report[link.name] = now
            self._report = (link, f"Signing: rejected {msg.get_type()} ({_reason(outcome)})")
        return False

    def pending_report(self):
        """(link, text) of a STATUSTEXT owed about a rejection, once; None when there is none."""
        report, self._report = self._report, None
        return report

    # ----------------------------------------------------------------------------------- SETUP_SIGNING
    def setup(self, msg, armed: bool) -> tuple[bool, str]:
        """Apply a SETUP_SIGNING that passed :meth:`admit` (so, with a key on, it was signed with it): (applied,
        what to say).  Refused while armed."""
        if armed:
            return False, "Signing: key change refused while armed: disarm first"
        key = SigningKey(bytes(msg.secret_key), int(msg.initial_timestamp))
        was_active = self.active
        self.verifier.set_key(key, timestamp_from_unix(self.unix_time()))
        stored = SigningKey(key.secret, self.verifier.timestamp) if key.enabled else DISABLED
        for link_id, link in enumerate(self.links):
            self._configure(link, link_id)
        if self.key_path is not None:
            signing.write_key_file(self.key_path, stored)
            where = f"saved to {self.key_path}"
        else:
            where = "for this run only (no --signing-key file to keep it in)"
        if not key.enabled:
            text = "Signing: disabled" if was_active else "Signing: stays off (blank key)"
        else:
            text = "Signing: key changed" if was_active else "Signing: enabled"
        log.info("%s, %s", text, where)
        return True, text

    # ------------------------------------------------------------------------------------ shutdown
    def close(self) -> None:
        """Write the signing clock back to the key file (PX4 does at a graceful shutdown) and log the counts."""
        if self.verifier.counts:
            log.info("signing: %s", self.verifier.summary())
        key = self.verifier.key
        if self.key_path is None or key is None:
            return
        clock = max([self.verifier.timestamp] + [link.signing_timestamp() for link in self.links])
        if signing.checkpoint_key_file(self.key_path, SigningKey(key.secret, clock)):
            log.info("signing: timestamp %d written back to %s", clock, self.key_path)

    def summary(self) -> dict:
        return self.verifier.summary()


def _reason(outcome: str) -> str:
    return {signing.REJECTED_UNSIGNED: "unsigned", signing.REJECTED_BAD_SIGNATURE: "bad signature",
            signing.REJECTED_REPLAY: "old timestamp", signing.REJECTED_OLD_STREAM: "stale stream",
            signing.REJECTED_STREAMS_FULL: "too many streams"}.get(outcome, outcome)
