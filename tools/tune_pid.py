"""PID analysis of the vehicle's control cascade: ``flowgap-tune-pid`` / ``python -m tools.tune_pid``.

Builds a linear single-axis model of each loop with python-control, from the inside out, each outer
loop seeing the inner loop closed:

* ``rate_rp`` / ``rate_yaw``: body-rate PID -> angular acceleration -> first-order motor lag -> 1/s;
  the rate loop runs every physics step (ZOH half-sample + one-sample compute delay, Pade 2nd order),
  the D term through its low-pass.
* ``attitude_rp`` / ``attitude_yaw``: attitude P around the closed rate loop, 1/s, the attitude loop's
  sample delay (yaw uses MC_YAW_P; the yaw-weighting only matters for large errors).
* ``velocity_xy``: velocity PID -> acceleration setpoint -> tilt (a = g*theta, small angle) through the
  closed attitude loop, linear drag, the position loop's sample delay.
* ``velocity_z``: velocity PID -> thrust through the motor lag, drag, sample delay.
* ``position_xy`` / ``position_z``: position P around the closed velocity loop, 1/s, sample delay.

For each loop it prints the gain margin, phase margin and crossover frequency, writes one closed-loop
step-response PNG per loop and ``margins.json`` into ``--out``. Exit status 0 when every loop has a
phase margin of at least ``--min-pm`` degrees, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import sys
from dataclasses import asdict
from pathlib import Path

import control as ct
import numpy as np

from sitl_vehicle.airframes import AIRFRAMES, Airframe
from sitl_vehicle.control.config import ControlConfig

log = logging.getLogger(__name__)

LOOPS = ("rate_rp", "rate_yaw", "attitude_rp", "attitude_yaw", "velocity_xy", "velocity_z",
         "position_xy", "position_z")


def _delay(seconds: float, order: int = 2):
    if seconds <= 0.0:
        return ct.tf([1.0], [1.0])
    num, den = ct.pade(seconds, order)
    return ct.tf(num, den)


def _pid(p: float, i: float, d: float, d_lpf_hz: float = 0.0):
    s = ct.tf("s")
    c = ct.tf([p], [1.0])
    if i:
        c = c + i / s
    if d:
        if d_lpf_hz > 0:
            wf = 2.0 * math.pi * d_lpf_hz
            c = c + d * s * wf / (s + wf)
        else:
            c = c + d * s
    return c


def loop_models(control: ControlConfig, airframe: Airframe, physics_hz: float = 500.0) -> dict:
    """Open-loop transfer functions ``{loop: (L, T_closed)}`` of every loop of the cascade."""
    s = ct.tf("s")
    dt = 1.0 / physics_hz
    motor = 1.0 / (airframe.motor_tau_s * s + 1.0)
    # rate loop: ZOH (dt/2) + one step of compute/actuation latency
    rate_delay = _delay(1.5 * dt)
    att_dt = max(round(physics_hz / control.attitude_hz), 1) * dt
    pos_dt = max(round(physics_hz / control.position_hz), 1) * dt
    att_delay = _delay(0.5 * att_dt)
    pos_delay = _delay(0.5 * pos_dt + dt)  # ZOH + the estimate is one step old
    out: dict[str, tuple] = {}

    def close(loop):
        return ct.feedback(loop, 1)

    for name, axis in (("rp", 0), ("yaw", 2)):
        c = _pid(control.rate_p[axis], control.rate_i[axis], control.rate_d[axis], control.rate_d_lpf_hz)
        lr = ct.minreal(c * motor * rate_delay / s, verbose=False)
        tr = close(lr)
        out[f"rate_{name}"] = (lr, tr)
        la = ct.minreal(control.att_p[axis] * tr * att_delay / s, verbose=False)
        out[f"attitude_{name}"] = (la, close(la))
    t_att = out["attitude_rp"][1]
    m = airframe.mass_kg
    cx, _, cz = airframe.drag_coeff_ns_per_m
    # horizontal: acceleration setpoint -> tilt setpoint a/g -> attitude loop -> a = g*theta
    cv = _pid(control.vel_p_xy, control.vel_i_xy, control.vel_d_xy)
    lv = ct.minreal(cv * t_att * pos_delay / (s + cx / m), verbose=False)
    out["velocity_xy"] = (lv, close(lv))
    cvz = _pid(control.vel_p_z, control.vel_i_z, control.vel_d_z)
    lvz = ct.minreal(cvz * motor * rate_delay * pos_delay / (s + cz / m), verbose=False)
    out["velocity_z"] = (lvz, close(lvz))
    lp = ct.minreal(control.pos_p_xy * out["velocity_xy"][1] * pos_delay / s, verbose=False)
    out["position_xy"] = (lp, close(lp))
    lpz = ct.minreal(control.pos_p_z * out["velocity_z"][1] * pos_delay / s, verbose=False)
    out["position_z"] = (lpz, close(lpz))
    return out


def margins(control: ControlConfig, airframe: Airframe, physics_hz: float = 500.0) -> dict[str, dict]:
    """Gain margin (dB), phase margin (deg) and crossover (rad/s) of every loop."""
    res = {}
    for name, (loop, closed) in loop_models(control, airframe, physics_hz).items():
        gm, pm, wcg, wcp = ct.margin(loop)
        gm_db = 20.0 * math.log10(gm) if gm and np.isfinite(gm) and gm > 0 else math.inf
        poles = ct.poles(closed)
        res[name] = {
            "gain_margin_db": float(gm_db),
            "phase_margin_deg": float(pm) if np.isfinite(pm) else math.inf,
            "crossover_rad_s": float(wcp) if np.isfinite(wcp) else float("nan"),
            "phase_crossover_rad_s": float(wcg) if np.isfinite(wcg) else float("nan"),
            "closed_loop_stable": bool(np.all(np.real(poles) < 0)),
        }
    return res


def step_responses(control: ControlConfig, airframe: Airframe, out_dir: Path, physics_hz: float = 500.0) -> list:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    files = []
    for name, (_, closed) in loop_models(control, airframe, physics_hz).items():
        t_end = {"rate": 0.3, "attitude": 1.0, "velocity": 4.0, "position": 8.0}[name.split("_")[0]]
        t = np.linspace(0.0, t_end, 600)
        resp = ct.step_response(closed, t)
        fig, ax = plt.subplots(figsize=(5, 3.2))
        ax.plot(resp.time, np.squeeze(resp.outputs), label="closed loop")
        ax.axhline(1.0, color="grey", lw=0.8, ls="--")
        ax.set_xlabel("time (s)")
        ax.set_ylabel("output / setpoint")
        ax.set_title(f"{airframe.name}: {name} step response")
        ax.grid(alpha=0.3)
        fig.tight_layout()
        path = out_dir / f"step_{name}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        files.append(path)
    return files


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="flowgap-tune-pid",
        description="Linear analysis of the sitl_vehicle control cascade (rate, attitude, velocity, position "
                    "loops with motor lag, inertia and loop delays as Pade approximations): prints gain and "
                    "phase margins per loop, writes step-response PNGs and margins.json.",
        epilog="Example: flowgap-tune-pid --airframe quad250 --out out/pid",
    )
    parser.add_argument("--airframe", choices=sorted(AIRFRAMES), default="quad250",
                        help="airframe to analyse (default: %(default)s)")
    parser.add_argument("--physics-hz", type=float, default=500.0,
                        help="physics / rate-loop frequency in Hz (default: %(default)s)")
    parser.add_argument("-o", "--out", type=Path, default=Path("out/tune_pid"),
                        help="output directory for PNGs and margins.json (default: %(default)s)")
    parser.add_argument("--min-pm", type=float, default=45.0,
                        help="required phase margin in degrees for exit status 0 (default: %(default)s)")
    parser.add_argument("--no-plots", action="store_true", help="skip the step-response PNGs")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")

    control = ControlConfig()
    airframe = AIRFRAMES[args.airframe]
    res = margins(control, airframe, args.physics_hz)
    args.out.mkdir(parents=True, exist_ok=True)
    files = [] if args.no_plots else step_responses(control, airframe, args.out, args.physics_hz)
    ok = all(r["phase_margin_deg"] >= args.min_pm and r["closed_loop_stable"] for r in res.values())
    (args.out / "margins.json").write_text(json.dumps(
        {"airframe": airframe.name, "physics_hz": args.physics_hz, "min_phase_margin_deg": args.min_pm,
         "all_ok": ok, "loops": res, "control": asdict(control)}, indent=2, default=str) + "\n")
    print(f"PID margins for {airframe.name} at {args.physics_hz:g} Hz physics:")
    print(f"{'loop':<14}{'GM (dB)':>9}{'PM (deg)':>10}{'wc (rad/s)':>12}  verdict")
    for name, r in res.items():
        verdict = "ok" if r["phase_margin_deg"] >= args.min_pm and r["closed_loop_stable"] else "LOW"
        print(f"{name:<14}{r['gain_margin_db']:>9.1f}{r['phase_margin_deg']:>10.1f}{r['crossover_rad_s']:>12.2f}  "
              f"{verdict}")
    print(f"wrote {args.out / 'margins.json'}" + (f" and {len(files)} PNGs" if files else ""))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
