"""Autopilot links: ``make_link("udpin://:14540")``. One backend so far (pymavlink); a MAVSDK backend behind
the same ``AutopilotLink`` interface is planned (see the README's *Not done*)."""

from __future__ import annotations

from pathlib import Path

from companion.link.base import AutopilotLink, Endpoint, LinkError, LinkLost, TelemetryCache, parse_endpoint

BACKENDS = ("pymavlink",)


def make_link(url: str, backend: str = "pymavlink", tlog_path: Path | None = None) -> AutopilotLink:
    if backend == "pymavlink":
        from companion.link.pymavlink_link import PymavlinkLink

        return PymavlinkLink(url, tlog_path=tlog_path)
    raise ValueError(f"unknown link backend {backend!r}; choose one of {BACKENDS}")


__all__ = ["AutopilotLink", "Endpoint", "LinkError", "LinkLost", "TelemetryCache", "make_link", "parse_endpoint"]
