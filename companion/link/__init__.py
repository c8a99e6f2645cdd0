"""Autopilot links: ``make_link("udpin://:14540", backend="pymavlink" | "mavsdk")``."""

from __future__ import annotations

from pathlib import Path

from companion.link.base import AutopilotLink, Endpoint, LinkError, LinkLost, TelemetryCache, parse_endpoint

BACKENDS = ("pymavlink", "mavsdk")


def make_link(url: str, backend: str = "pymavlink", tlog_path: Path | None = None, clock=None,
              signing_key: Path | None = None) -> AutopilotLink:
    """A link to the autopilot at ``url``; ``clock`` (:mod:`companion.clock`, default the wall clock) paces it;
    ``signing_key`` (a PX4 key file, :mod:`companion.link.signing`) signs what it sends and checks what comes."""
    if backend == "pymavlink":
        from companion.link.pymavlink_link import PymavlinkLink

        key = None
        if signing_key is not None:
            from companion.link.signing import load_key

            key = load_key(signing_key)
        return PymavlinkLink(url, tlog_path=tlog_path, clock=clock, signing_key=key)
    if signing_key is not None:
        raise ValueError(f"the {backend} link cannot sign MAVLink (mavsdk_server has no message signing): use "
                         f"--link pymavlink with --signing-key")
    if backend == "mavsdk":
        if clock is not None and clock.name != "wall":
            raise ValueError("the mavsdk link cannot run in lockstep: mavsdk_server keeps its own wall-clock "
                             "timers and threads, which no simulated clock can hold; use --link pymavlink")
        from companion.link.mavsdk_link import MavsdkLink

        return MavsdkLink(url)  # MAVSDK hides the packets: no .tlog from this backend
    raise ValueError(f"unknown link backend {backend!r}; choose one of {BACKENDS}")


__all__ = ["AutopilotLink", "Endpoint", "LinkError", "LinkLost", "TelemetryCache", "make_link", "parse_endpoint"]
