"""Collision checking of the vehicle's body sphere against the world (ground truth, every physics step).

A world is anything satisfying :class:`CollisionWorld`: ``clearance(p)`` is the distance (m) from the
point ``p`` (NED) to the nearest solid obstacle surface, negative inside; the ground is *not* part of it
(the dynamics handles the ground). ``wall_x`` (optional) is the NED x of the wall plane's front face,
used for the "crossed the wall" verdict. ``gate`` (optional; a capture scene's) is a rectangle the flight must
cross: it offers ``signed_distance(p)`` (negative on the side the vehicle comes from), ``crossing_point(p0, s0,
p1, s1)``, ``contains(p)`` and ``describe()``. ``scenes.collision`` supplies real worlds; :class:`GroundOnly`
is the default.

:class:`CollisionMonitor` turns a sphere contact (``clearance(p) <= body_radius``) or a hard ground
impact (vertical touchdown speed above ``crash_speed_mps``) into a crash, and tracks the minimum
clearance (surface to sphere, m) and whether the centre crossed ``x > wall_x`` or, with a gate, the gate's plane
from its approach side (``crossed_wall``) and its rectangle (``gate_crossed``, where and when: checked on the
segment between successive physics steps, so that no crossing slips between two).
"""

from __future__ import annotations

import math
from typing import Protocol, runtime_checkable


@runtime_checkable
class CollisionWorld(Protocol):
    def clearance(self, p: tuple[float, float, float]) -> float:
        """Distance (m) from ``p`` to the nearest obstacle surface (ground excluded); negative inside."""
        ...


class GroundOnly:
    """No obstacles: infinite clearance, no wall."""

    wall_x: float | None = None

    def clearance(self, p: tuple[float, float, float]) -> float:
        return math.inf


class CollisionMonitor:
    def __init__(self, world: CollisionWorld | None, body_radius_m: float, crash_speed_mps: float = 2.0):
        self.world = world if world is not None else GroundOnly()
        self.body_radius_m = float(body_radius_m)
        self.crash_speed_mps = float(crash_speed_mps)
        self.wall_x: float | None = getattr(self.world, "wall_x", None)
        self.gate = getattr(self.world, "gate", None)
        self._trivial = isinstance(self.world, GroundOnly)
        self.reset()

    def reset(self) -> None:
        self.crashed = False
        self.crash_reason: str | None = None
        self.crash_time_s: float | None = None
        self.min_clearance_m = math.inf
        self.crossed_wall = False
        self.gate_crossed = False
        self.gate_crossed_at: tuple[float, float, float] | None = None
        self.gate_crossed_time_s: float | None = None
        self._gate_prev: tuple | None = None          # (position, signed distance) at the last step

    def gate_report(self) -> dict | None:
        """The gate and whether, where and when the centre crossed its rectangle (None without a gate)."""
        if self.gate is None:
            return None
        at = self.gate_crossed_at
        return {**self.gate.describe(), "crossed": self.gate_crossed,
                "crossed_at_ned": None if at is None else [round(v, 4) for v in at],
                "crossed_time_s": None if self.gate_crossed_time_s is None else round(self.gate_crossed_time_s, 4)}

    def check(self, position, t: float, touchdown_speed_mps: float | None = None) -> bool:
        """Check one physics step; returns True when this step crashed. ``touchdown_speed_mps`` is the
        downward speed of a ground contact that began in this step (None = no new contact)."""
        if self.crashed:
            return False
        if not self._trivial:
            c = self.world.clearance(position) - self.body_radius_m
            if c < self.min_clearance_m:
                self.min_clearance_m = c
            if c <= 0.0:
                return self._crash(t, f"collision with obstacle at ({position[0]:.2f}, {position[1]:.2f}, "
                                      f"{position[2]:.2f}) m, clearance {c:.3f} m")
            wx = self.wall_x
            if wx is not None and position[0] > wx:
                self.crossed_wall = True
            if self.gate is not None:
                self._check_gate(position, t)
        if touchdown_speed_mps is not None and touchdown_speed_mps > self.crash_speed_mps:
            return self._crash(t, f"hard ground impact at {touchdown_speed_mps:.2f} m/s "
                                  f"(limit {self.crash_speed_mps:.2f} m/s)")
        return False

    def _check_gate(self, position, t: float) -> None:
        gate = self.gate
        s = gate.signed_distance(position)
        prev = self._gate_prev
        self._gate_prev = (position, s)
        if prev is None or not prev[1] < 0.0 <= s:
            return
        self.crossed_wall = True
        if not self.gate_crossed:
            point = gate.crossing_point(prev[0], prev[1], position, s)
            if gate.contains(point):
                self.gate_crossed = True
                self.gate_crossed_at = point
                self.gate_crossed_time_s = t

    def _crash(self, t: float, reason: str) -> bool:
        self.crashed = True
        self.crash_reason = reason
        self.crash_time_s = t
        return True
