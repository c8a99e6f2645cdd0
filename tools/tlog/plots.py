"""PNG plots of a :class:`~tools.tlog.analysis.Report` (matplotlib, Agg backend).

Axes follow NED: x north (forward, towards the wall), y east (right), altitude = -z. With a scene, the
wall (plane x = wall_x, thickness to wall_back_x) and its openings (polygons in (y, z)) are drawn in.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)


def scene_geometry(spec: Any) -> dict[str, Any]:
    """Wall and openings from a ``scenes`` spec, read by duck typing (raises ValueError if unreadable).

    Returns {"wall_x", "wall_back_x", "wall_y": (min, max) or None, "wall_z": (min, max) or None,
    "openings": [array (k, 2) of (y, z)]}.
    """
    try:
        wall_x = float(spec.wall_x() if callable(getattr(spec, "wall_x", None)) else spec.wall_x)
    except AttributeError:
        try:
            wall_x = float(spec.wall.distance)
        except AttributeError as exc:
            raise ValueError("scene spec has neither wall_x nor wall.distance") from exc
    back = getattr(spec, "wall_back_x", None)
    wall_back_x = float(back) if isinstance(back, int | float) else wall_x
    wall = getattr(spec, "wall", None)
    wall_y = wall_z = None
    if wall is not None and hasattr(wall, "width"):
        cy = float(getattr(wall, "center_y", 0.0))
        wall_y = (cy - float(wall.width) / 2, cy + float(wall.width) / 2)
        if hasattr(wall, "height"):
            wall_z = (-float(wall.height), 0.0)
    openings = []
    for op in getattr(spec, "openings", ()) or ():
        poly = op.polygon() if callable(getattr(op, "polygon", None)) else getattr(op, "polygon", op)
        arr = np.asarray(poly, dtype=float)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise ValueError(f"opening outline has shape {arr.shape}, expected (k, 2) in (y, z)")
        openings.append(arr)
    return {"wall_x": wall_x, "wall_back_x": wall_back_x, "wall_y": wall_y, "wall_z": wall_z,
            "openings": openings}


def load_scene_geometry(name: str) -> tuple[dict[str, Any] | None, str | None]:
    """(geometry, None) or (None, note) when the ``scenes`` package or the scene is unavailable.

    Uses ``scenes.build.resolve_spec(name)`` (spec only, no splats built) when it exists, else
    ``scenes.load_scene(name)``, which may return the spec or a ``(spec, cloud)`` tuple.
    """
    try:
        import scenes
    except ImportError as exc:
        return None, f"--scene {name}: the scenes package is not available ({exc}); plots drawn without it"
    loader = None
    try:
        from scenes.build import resolve_spec as loader
    except ImportError:
        loader = getattr(scenes, "load_scene", None)
    if loader is None:
        return None, f"--scene {name}: scenes.load_scene does not exist yet; plots drawn without the wall"
    try:
        spec = loader(name)
        if isinstance(spec, tuple):
            spec = next((x for x in spec if hasattr(x, "wall") or hasattr(x, "wall_x")), None)
        if spec is None:
            return None, f"--scene {name}: no scene spec (wall, openings) for it; plots drawn without it"
        return scene_geometry(spec), None
    except Exception as exc:  # noqa: BLE001 - any failure in a sibling package becomes a note
        msg = str(exc).splitlines()[0] if str(exc) else ""
        return None, f"--scene {name}: could not load the scene ({type(exc).__name__}: {msg}); plots drawn without it"


def wall_crossings(t: np.ndarray, xyz: np.ndarray, geo: dict[str, Any]) -> list[dict[str, Any]]:
    """Where a trajectory crosses the wall's front plane x = wall_x (linear interpolation), and whether
    that point lies inside an opening: [{"t_s", "y", "z", "direction", "through_opening"}]."""
    from matplotlib.path import Path as MplPath

    if xyz.shape[0] < 2:
        return []
    d = xyz[:, 0] - geo["wall_x"]
    k = np.flatnonzero((d[:-1] < 0) != (d[1:] < 0))
    paths = [MplPath(o) for o in geo["openings"]]
    out = []
    for i in k.tolist():
        a = d[i] / (d[i] - d[i + 1])
        y, z = (xyz[i, 1:] + a * (xyz[i + 1, 1:] - xyz[i, 1:])).tolist()
        out.append({"t_s": float(t[i] + a * (t[i + 1] - t[i])), "y": y, "z": z,
                    "direction": "forward" if d[i + 1] > d[i] else "backward",
                    "through_opening": any(p.contains_point((y, z)) for p in paths)})
    return out


def _opening_span(openings: list[np.ndarray], col: int) -> list[tuple[float, float]]:
    return [(float(o[:, col].min()), float(o[:, col].max())) for o in openings]


def _wall_line(ax: Any, geo: dict[str, Any], col: int, full: tuple[float, float] | None, sign: float) -> None:
    """Draw the wall as a band x ∈ [wall_x, wall_back_x] with gaps where openings are (col 0: y, 1: z)."""
    spans = sorted(tuple(sorted((sign * a, sign * b))) for a, b in _opening_span(geo["openings"], col))
    if full is not None:
        lo, hi = sorted((sign * full[0], sign * full[1]))
    else:
        vals = [v for span in spans for v in span] or [0.0]
        lo, hi = min(vals) - 2.0, max(vals) + 2.0
    x0, x1 = geo["wall_x"], max(geo["wall_back_x"], geo["wall_x"] + 0.02)
    cur = lo
    for a, b in spans + [(hi, hi)]:
        if a > cur:
            ax.fill_betweenx([cur, min(a, hi)], x0, x1, color="0.35", alpha=0.8, lw=0)
        cur = max(cur, b)
    for a, b in spans:
        ax.fill_betweenx([a, b], x0, x1, color="tab:green", alpha=0.25, lw=0,
                         label="opening" if a == spans[0][0] else None)
    ax.plot([], [], color="0.35", lw=6, label="wall")


def make_plots(rep: Any, out_dir: Path, scene: dict[str, Any] | None = None) -> dict[str, str]:
    """Write the PNGs into ``out_dir``; returns {plot name: file name}. Skips plots without data."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    s = rep.series
    out: dict[str, str] = {}
    est = s.get("est", np.zeros((0, 3)))
    sp = s.get("sp", np.zeros((0, 3)))
    truth = s.get("truth")
    has_pos = est.size > 0 or sp.size > 0 or (truth is not None and truth.size > 0)

    def series_xy(ax: Any, a: int, b: int, signb: float) -> None:
        if est.size:
            ax.plot(est[:, a], signb * est[:, b], lw=1.2, color="tab:blue", label="estimate")
        if truth is not None and truth.size:
            ax.plot(truth[:, a], signb * truth[:, b], lw=1.0, color="k", ls="--", label="truth")
        if sp.size:
            ax.plot(sp[:, a], signb * sp[:, b], ".", ms=2.5, color="tab:orange", label="setpoints")

    if has_pos:
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 8.5))
        series_xy(ax1, 0, 1, 1.0)
        ax1.set_xlabel("x north / forward [m]")
        ax1.set_ylabel("y east / right [m]")
        ax1.set_title("top-down (NED, y east plotted upwards)")
        series_xy(ax2, 0, 2, -1.0)
        ax2.set_xlabel("x north / forward [m]")
        ax2.set_ylabel("altitude −z [m]")
        ax2.set_title("side view")
        if scene is not None:
            _wall_line(ax1, scene, 0, scene.get("wall_y"), 1.0)
            _wall_line(ax2, scene, 1, scene.get("wall_z"), -1.0)
        for ax in (ax1, ax2):
            ax.grid(alpha=0.3)
            ax.set_aspect("equal", adjustable="datalim")
            ax.legend(loc="best", fontsize=8)
        fig.tight_layout()
        fig.savefig(out_dir / "trajectory.png", dpi=110)
        plt.close(fig)
        out["trajectory"] = "trajectory.png"
        if scene is not None and scene["openings"]:
            fig, ax = plt.subplots(figsize=(6, 5))
            for k, o in enumerate(scene["openings"]):
                ring = np.vstack([o, o[:1]])
                ax.fill(ring[:, 0], -ring[:, 1], color="tab:green", alpha=0.25,
                        label="opening" if k == 0 else None)
            near = np.abs(est[:, 0] - scene["wall_x"]) < 0.5 if est.size else np.zeros(0, dtype=bool)
            if near.any():
                ax.plot(est[near, 1], -est[near, 2], ".", ms=3, color="tab:blue", label="estimate |x−wall|<0.5 m")
            if truth is not None and truth.size:
                nt = np.abs(truth[:, 0] - scene["wall_x"]) < 0.5
                if nt.any():
                    ax.plot(truth[nt, 1], -truth[nt, 2], ".", ms=3, color="k", label="truth |x−wall|<0.5 m")
            ax.set_xlabel("y east / right [m]")
            ax.set_ylabel("altitude −z [m]")
            ax.set_title("wall plane, seen from the start")
            ax.set_aspect("equal", adjustable="datalim")
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8)
            fig.tight_layout()
            fig.savefig(out_dir / "wall_plane.png", dpi=110)
            plt.close(fig)
            out["wall_plane"] = "wall_plane.png"
    if est.size:
        t = s["t_est"]
        fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
        ax1.plot(t, -est[:, 2], color="tab:blue", label="estimate")
        if truth is not None and truth.size:
            ax1.plot(s["t_truth"], -truth[:, 2], color="k", ls="--", lw=1, label="truth")
        if sp.size:
            ax1.plot(s["t_sp"], -sp[:, 2], ".", ms=2.5, color="tab:orange", label="setpoint")
        ax1.set_ylabel("altitude −z [m]")
        ax1.legend(fontsize=8)
        ax1.grid(alpha=0.3)
        vel = s["vel"]
        ax2.plot(t, np.linalg.norm(vel, axis=1), color="tab:purple", label="|v| (3-D)")
        ax2.plot(t, np.linalg.norm(vel[:, :2], axis=1), color="tab:cyan", lw=1, label="horizontal")
        ax2.set_ylabel("speed [m/s]")
        ax2.set_xlabel("time [s]")
        ax2.legend(fontsize=8)
        ax2.grid(alpha=0.3)
        fig.tight_layout()
        fig.savefig(out_dir / "altitude_speed.png", dpi=110)
        plt.close(fig)
        out["altitude_speed"] = "altitude_speed.png"
    has_err = s.get("err") is not None and len(s["err"])
    has_err_truth = s.get("err_truth") is not None and len(s["err_truth"])
    if has_err or has_err_truth:
        fig, ax = plt.subplots(figsize=(9, 3.5))
        if has_err:
            ax.plot(s["t_err"], s["err"], color="tab:red", lw=1, label="|estimate − setpoint|")
        if has_err_truth:
            ax.plot(s["t_err_truth"], s["err_truth"], color="k", lw=0.8, alpha=0.7, label="|truth − setpoint|")
        for a, b in rep.metrics.get("offboard", {}).get("offboard_intervals_s", []):
            ax.axvspan(a, b, color="tab:green", alpha=0.08)
        ax.set_xlabel("time [s]")
        ax.set_ylabel("tracking error [m]")
        ax.set_title("position tracking error (green: offboard mode)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out_dir / "tracking_error.png", dpi=110)
        plt.close(fig)
        out["tracking_error"] = "tracking_error.png"
    timeline = rep.metrics.get("modes", {}).get("timeline", [])
    if timeline:
        fig, ax = plt.subplots(figsize=(10, 2.2))
        names = sorted({e["mode"] for e in timeline})
        cmap = plt.get_cmap("tab10")
        for e in timeline:
            k = names.index(e["mode"])
            ax.barh(0, e["until_s"] - e["t_s"], left=e["t_s"], color=cmap(k % 10), edgecolor="none",
                    label=e["mode"])
        for ev in rep.metrics.get("arm_events", []):
            ax.axvline(ev["t_s"], color="k", lw=1.2, ls="-" if ev["event"] == "arm" else ":")
            ax.text(ev["t_s"], 0.45, ev["event"], fontsize=7, ha="left", va="bottom")
        handles, labels = ax.get_legend_handles_labels()
        uniq = dict(zip(labels, handles, strict=True))
        ax.legend(uniq.values(), uniq.keys(), fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0),
                  frameon=False)
        ax.set_yticks([])
        ax.set_ylim(-0.5, 0.8)
        ax.set_xlabel("time [s]")
        ax.set_title("flight modes (solid line: arm, dotted: disarm)")
        fig.tight_layout()
        fig.savefig(out_dir / "modes.png", dpi=110)
        plt.close(fig)
        out["modes"] = "modes.png"
    return out
