"""Trapezoidal point-to-point reference generation and acceleration-limited velocity setpoints.

:class:`TrapezoidPlanner` turns a position target into a reference ``p_ref(t), v_ref(t), a_ref(t)``:

* the move starts from the *current reference* position and velocity (``p0, v0``), so changing the
  target mid-flight never makes the reference jump;
* the straight line ``p0 -> target`` (direction ``e``) gets a 1-D time-optimal trapezoidal velocity
  profile (triangular when the distance is too short to reach ``v_max``) that starts at the along-line
  part of ``v0`` (``v0 . e``; if that is faster than ``v_max`` it first slows down, if it points away
  it first brakes, if it cannot stop before the target it brakes, overshoots and comes back);
* the off-line part of ``v0`` (``v0_perp``) is handled by a second 1-D profile along ``v0_perp``'s
  direction that brakes it with ``a_max`` and then returns the offset to zero (brake-and-return).
  So the reference blends smoothly from the old motion onto the new line and ends exactly at the
  target at rest. With ``v0 = 0`` (the usual case: a new waypoint after arriving) the move is a pure
  straight-line trapezoid.
* limits depend on direction: along a unit vector ``u`` the speed limit is the largest ``s`` with
  ``s*|u_xy| <= v_max_xy`` and ``s*|u_z| <= v_max_up/down``; likewise for acceleration.
* a target equal (within ``retarget_tolerance_m``) to the current one does nothing: clients stream the
  same setpoint at 10-50 Hz and that must never restart the profile.
* target components that are NaN are not planned: those axes keep zero displacement in the plan and
  the sampled reference is NaN there (the caller controls them in velocity).

:class:`VelocitySlew` is the velocity-setpoint path: it bypasses the planner but slews the velocity
reference towards the setpoint with at most ``a_max_xy`` (horizontal, as a vector) and ``a_max_z``.

Pure: times are passed in, nothing reads a clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

NAN = float("nan")


@dataclass(frozen=True)
class PlannerConfig:
    v_max_xy: float = 2.0  # m/s, horizontal speed limit of planned moves (MPC_XY_CRUISE)
    v_max_up: float = 1.0  # m/s, climb speed limit (MPC_Z_V_AUTO_UP)
    v_max_down: float = 0.7  # m/s, descent speed limit (MPC_Z_V_AUTO_DN)
    a_max_xy: float = 3.0  # m/s^2, horizontal acceleration limit (MPC_ACC_HOR)
    a_max_z: float = 2.0  # m/s^2, vertical acceleration limit (MPC_ACC_UP_MAX / MPC_ACC_DOWN_MAX)
    retarget_tolerance_m: float = 1e-3  # m, a target closer than this to the current one is "the same"


Segment = tuple[float, float, float, float]  # (t_start s, x_start m, v_start m/s, accel m/s^2)


def plan_1d(dist: float, v0: float, vmax: float, amax: float) -> tuple[list[Segment], float]:
    """Time-optimal 1-D profile from ``(0, v0)`` to ``(dist, 0)`` with ``|v| <= vmax`` (after any initial
    excess is braked) and ``|a| <= amax``. Returns constant-acceleration segments and the total time."""
    if dist < 0.0:
        segs, total = plan_1d(-dist, -v0, vmax, amax)
        return [(t, -x, -v, -a) for t, x, v, a in segs], total
    segs: list[Segment] = []
    t = x = 0.0
    v = v0

    def push(dur: float, a: float) -> None:
        nonlocal t, x, v
        if dur > 1e-12:
            segs.append((t, x, v, a))
            t += dur
            x += v * dur + 0.5 * a * dur * dur
            v += a * dur

    if v < 0.0:
        push(-v / amax, amax)
        v = 0.0
    if v > vmax:
        push((v - vmax) / amax, -amax)
        v = vmax
    rem = dist - x
    if v * v / (2.0 * amax) > rem + 1e-9:
        push(v / amax, -amax)  # cannot stop in time: brake, overshoot, come back
        v = 0.0
        back, tb = plan_1d(dist - x, 0.0, vmax, amax)
        segs.extend((t + ts, x + xs, vs, a) for ts, xs, vs, a in back)
        return segs, t + tb
    vp = min(math.sqrt(max(amax * rem + 0.5 * v * v, 0.0)), vmax)
    d1 = (vp * vp - v * v) / (2.0 * amax)
    d3 = vp * vp / (2.0 * amax)
    push((vp - v) / amax, amax)
    if vp > 1e-12:
        push(max(rem - d1 - d3, 0.0) / vp, 0.0)
    push(vp / amax, -amax)
    return segs, t


def sample_1d(segs: list[Segment], total: float, end: float, t: float) -> tuple[float, float, float]:
    """Position, velocity, acceleration of a :func:`plan_1d` profile at time ``t`` (s)."""
    if t >= total or not segs:
        return end, 0.0, 0.0
    if t <= 0.0:
        t0, x0, v0, a = segs[0]
        return x0, v0, a
    seg = segs[0]
    for s in segs:
        if s[0] <= t:
            seg = s
        else:
            break
    t0, x0, v0, a = seg
    dt = t - t0
    return x0 + v0 * dt + 0.5 * a * dt * dt, v0 + a * dt, a


def _dir_limit(u, lim_xy: float, lim_up: float, lim_down: float) -> float:
    """Largest scalar ``s`` such that ``s*u`` respects the horizontal and vertical limits."""
    nxy = math.hypot(u[0], u[1])
    s = math.inf
    if nxy > 1e-9:
        s = lim_xy / nxy
    if abs(u[2]) > 1e-9:
        s = min(s, (lim_down if u[2] > 0.0 else lim_up) / abs(u[2]))
    return s


class TrapezoidPlanner:
    """Straight-line 3-D trapezoidal reference; see the module docstring for the behaviour."""

    def __init__(self, config: PlannerConfig = PlannerConfig()):
        self.config = config
        self._target: tuple[float, float, float] | None = None
        self._mask = (True, True, True)
        self._t0 = 0.0
        self._p0 = (0.0, 0.0, 0.0)
        self._e = (0.0, 0.0, 0.0)
        self._e_perp = (0.0, 0.0, 0.0)
        self._line: tuple[list[Segment], float, float] = ([], 0.0, 0.0)
        self._perp: tuple[list[Segment], float, float] = ([], 0.0, 0.0)
        self.restarts = 0  # number of (re)plans, for tests and diagnostics

    @property
    def target(self) -> tuple[float, float, float] | None:
        return self._target

    @property
    def active(self) -> bool:
        return self._target is not None

    @property
    def duration(self) -> float:
        """Time (s) from the last (re)plan until the reference comes to rest at the target."""
        return max(self._line[1], self._perp[1])

    def clear(self) -> None:
        """Forget the target (e.g. when switching to velocity control)."""
        self._target = None

    def set_config(self, config: PlannerConfig) -> None:
        """New limits apply to the next (re)plan (:meth:`replan` for the move under way); the current move
        continues unchanged."""
        self.config = config

    def is_same_target(self, target) -> bool:
        if self._target is None:
            return False
        tol = self.config.retarget_tolerance_m
        for a, b in zip(self._target, target, strict=False):
            fa, fb = math.isfinite(a), math.isfinite(b)
            if fa != fb or (fa and abs(a - b) > tol):
                return False
        return True

    def set_target(self, target, t: float, p_now=None, v_now=None) -> bool:
        """Plan towards ``target`` (NED m, NaN = axis not planned) at time ``t`` (s).

        Starts from the current reference if one is active, else from ``p_now``/``v_now`` (the state).
        Returns False (and changes nothing) if ``target`` equals the current target.
        """
        target = tuple(float(c) for c in target)
        if self.is_same_target(target):
            return False
        self._plan_to(target, t, p_now, v_now)
        return True

    def replan(self, t: float) -> bool:
        """Plan the current target again from the reference at time ``t`` (s), under the limits set now: how a new
        cruise speed applies to the move under way. Returns False (and changes nothing) when idle. (The same target
        plans the same axes, so the state is not needed: unplanned axes stay out of the plan.)"""
        if self._target is None:
            return False
        self._plan_to(self._target, t, None, None)
        return True

    def _plan_to(self, target: tuple[float, float, float], t: float, p_now, v_now) -> None:
        if self._target is not None:
            p0, v0, _ = self.sample(t)
            # axes not planned before continue from the state
            p0 = tuple(p if math.isfinite(p) else float(pn) for p, pn in zip(p0, p_now or (0.0,) * 3, strict=False))
            v0 = tuple(v if math.isfinite(v) else float(vn) for v, vn in zip(v0, v_now or (0.0,) * 3, strict=False))
        else:
            if p_now is None:
                raise ValueError("the first target needs the current position p_now")
            p0 = tuple(float(c) for c in p_now)
            v0 = tuple(float(c) for c in (v_now if v_now is not None else (0.0, 0.0, 0.0)))
        v0 = tuple(c if math.isfinite(c) else 0.0 for c in v0)
        mask = tuple(math.isfinite(c) for c in target)
        # unplanned axes: no displacement and no velocity in the plan
        goal = tuple(g if m else p for g, p, m in zip(target, p0, mask, strict=False))
        v0 = tuple(v if m else 0.0 for v, m in zip(v0, mask, strict=False))
        self._plan(goal, t, p0, v0)
        self._target = target
        self._mask = mask
        self.restarts += 1

    def _plan(self, goal, t: float, p0, v0) -> None:
        c = self.config
        d = (goal[0] - p0[0], goal[1] - p0[1], goal[2] - p0[2])
        dist = math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        if dist > 1e-9:
            e = (d[0] / dist, d[1] / dist, d[2] / dist)
        else:
            e, dist = (0.0, 0.0, 0.0), 0.0
        vpar = v0[0] * e[0] + v0[1] * e[1] + v0[2] * e[2]
        vperp = (v0[0] - vpar * e[0], v0[1] - vpar * e[1], v0[2] - vpar * e[2])
        nperp = math.sqrt(vperp[0] ** 2 + vperp[1] ** 2 + vperp[2] ** 2)
        if dist > 0.0:
            vmax = _dir_limit(e, c.v_max_xy, c.v_max_up, c.v_max_down)
            amax = _dir_limit(e, c.a_max_xy, c.a_max_z, c.a_max_z)
            segs, total = plan_1d(dist, vpar, vmax, amax)
            self._line = (segs, total, dist)
        else:
            self._line = ([], 0.0, 0.0)
        if nperp > 1e-9:
            ep = (vperp[0] / nperp, vperp[1] / nperp, vperp[2] / nperp)
            vmin_z = min(c.v_max_up, c.v_max_down)
            vmax_p = _dir_limit(ep, c.v_max_xy, vmin_z, vmin_z)
            amax_p = _dir_limit(ep, c.a_max_xy, c.a_max_z, c.a_max_z)
            segs, total = plan_1d(0.0, nperp, vmax_p, amax_p)
            self._perp = (segs, total, 0.0)
            self._e_perp = ep
        else:
            self._perp = ([], 0.0, 0.0)
            self._e_perp = (0.0, 0.0, 0.0)
        self._t0 = t
        self._p0 = p0
        self._e = e

    def sample(self, t: float) -> tuple[tuple[float, float, float], tuple[float, float, float],
                                        tuple[float, float, float]]:
        """Reference ``(p_ref, v_ref, a_ref)`` at time ``t`` (s); NaN on unplanned axes or when idle."""
        if self._target is None:
            n3 = (NAN, NAN, NAN)
            return n3, n3, n3
        tau = t - self._t0
        s, sv, sa = sample_1d(self._line[0], self._line[1], self._line[2], tau)
        q, qv, qa = sample_1d(self._perp[0], self._perp[1], self._perp[2], tau)
        e, ep, p0, m = self._e, self._e_perp, self._p0, self._mask
        p = [p0[i] + e[i] * s + ep[i] * q for i in range(3)]
        v = [e[i] * sv + ep[i] * qv for i in range(3)]
        a = [e[i] * sa + ep[i] * qa for i in range(3)]
        if tau >= self.duration:
            # snap exactly onto the target at the end
            p = [self._target[i] if m[i] else p[i] for i in range(3)]
        for i in range(3):
            if not m[i]:
                p[i] = v[i] = a[i] = NAN
        return (p[0], p[1], p[2]), (v[0], v[1], v[2]), (a[0], a[1], a[2])


class VelocitySlew:
    """Acceleration-limited velocity reference for velocity setpoints (bypasses the planner)."""

    def __init__(self, config: PlannerConfig = PlannerConfig()):
        self.config = config
        self.v_ref = (NAN, NAN, NAN)
        self.a_ref = (0.0, 0.0, 0.0)

    def reset(self, v=(NAN, NAN, NAN)) -> None:
        self.v_ref = tuple(float(c) for c in v)
        self.a_ref = (0.0, 0.0, 0.0)

    def update(self, v_sp, dt: float, v_now=(0.0, 0.0, 0.0)):
        """Move ``v_ref`` towards ``v_sp`` (NaN axes: not controlled -> NaN out); returns ``(v_ref, a_ref)``.

        An axis that becomes controlled starts from ``v_now`` (the current velocity) so it never jumps.
        """
        c = self.config
        cur = [r if math.isfinite(r) else float(n) for r, n in zip(self.v_ref, v_now, strict=False)]
        want = [float(x) for x in v_sp]
        if math.isfinite(want[2]):
            want[2] = min(max(want[2], -c.v_max_up), c.v_max_down)
        # horizontal
        ax = ay = az = 0.0
        if math.isfinite(want[0]) and math.isfinite(want[1]):
            n = math.hypot(want[0], want[1])
            if n > c.v_max_xy:
                want[0] *= c.v_max_xy / n
                want[1] *= c.v_max_xy / n
            dx, dy = want[0] - cur[0], want[1] - cur[1]
            dn = math.hypot(dx, dy)
            step = c.a_max_xy * dt
            if dn > step:
                dx, dy = dx / dn * step, dy / dn * step
            cur[0] += dx
            cur[1] += dy
            ax, ay = dx / dt, dy / dt
        else:
            cur[0] = cur[1] = NAN
            ax = ay = NAN
        if math.isfinite(want[2]):
            dz = want[2] - cur[2]
            step = c.a_max_z * dt
            dz = min(max(dz, -step), step)
            cur[2] += dz
            az = dz / dt
        else:
            cur[2] = NAN
            az = NAN
        self.v_ref = (cur[0], cur[1], cur[2])
        self.a_ref = (ax, ay, az)
        return self.v_ref, self.a_ref
