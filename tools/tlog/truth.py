"""Where the vehicle truly was, and how far a position series is from the setpoints before it (pure numpy).

The message types that may carry the true position (:data:`TRUTH_SOURCES`, tried in order by ``--truth auto``),
the ``--truth`` option's parser, and the tracking error of :func:`tools.tlog.analysis.analyse_tlog`: each position
sample against the latest position setpoint logged before it (:func:`latest_before`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

MAV_ESTIMATOR_TYPE_MOCAP = 6
LOCAL_FRAMES = (1, 18, 20)  # MAV_FRAME_LOCAL_NED, MAV_FRAME_MOCAP_NED, MAV_FRAME_LOCAL_FRD


def _external_only(rows: np.ndarray, from_estimator: np.ndarray) -> np.ndarray:
    return ~from_estimator


def _odometry_truth(rows: np.ndarray, from_estimator: np.ndarray) -> np.ndarray:
    """ODOMETRY in a local frame that is marked as motion capture (flowgap's simulator truth stream is
    ODOMETRY LOCAL_NED, estimator MOCAP, from the autopilot's own ids), or comes from another component."""
    local = np.isin(rows["frame_id"], LOCAL_FRAMES)
    return local & ((rows["estimator_type"] == MAV_ESTIMATOR_TYPE_MOCAP) | ~from_estimator)


def _any(rows: np.ndarray, from_estimator: np.ndarray) -> np.ndarray:
    return np.ones(rows.size, dtype=bool)


@dataclass(frozen=True)
class TruthSource:
    """A message type that may carry the vehicle's true position (x, y, z fields, NED metres).

    ``accept(rows, from_estimator)`` picks the rows that count as truth; ``from_estimator`` marks rows sent
    by the component whose LOCAL_POSITION_NED is the estimate.
    """

    name: str
    message: str
    description: str
    accept: Callable[[np.ndarray, np.ndarray], np.ndarray] = _any

    def positions(self, rows: np.ndarray) -> np.ndarray:
        return np.stack([rows["x"], rows["y"], rows["z"]], axis=1).astype(np.float64)


TRUTH_SOURCES: dict[str, TruthSource] = {
    s.name: s for s in (
        TruthSource("att_pos_mocap", "ATT_POS_MOCAP", "motion-capture / simulator pose"),
        TruthSource("odometry", "ODOMETRY", "ODOMETRY marked MOCAP, or from a non-estimator component",
                    _odometry_truth),
        TruthSource("local_position_ned_cov", "LOCAL_POSITION_NED_COV", "position with covariance",
                    _external_only),
        TruthSource("local_position_ned", "LOCAL_POSITION_NED", "a second LOCAL_POSITION_NED stream",
                    _external_only),
    )
}
TRUTH_AUTO_ORDER = tuple(TRUTH_SOURCES)


def parse_truth_option(text: str) -> tuple[str, tuple[int, int] | None]:
    """``auto`` | ``none`` | ``NAME`` | ``NAME@SYSID:COMPID`` → (name, source or None)."""
    text = text.strip().lower()
    src = None
    if "@" in text:
        text, _, where = text.partition("@")
        sys_s, _, comp_s = where.partition(":")
        src = (int(sys_s), int(comp_s))
    if text not in ("auto", "none") and text not in TRUTH_SOURCES:
        raise ValueError(f"unknown truth source {text!r}; use auto, none or one of {sorted(TRUTH_SOURCES)}")
    return text, src


def error_stats(err: np.ndarray) -> dict[str, Any]:
    if err.size == 0:
        return {"n_samples": 0}
    return {"n_samples": int(err.size), "mean_m": float(err.mean()), "rms_m": float(np.sqrt((err ** 2).mean())),
            "median_m": float(np.median(err)), "p95_m": float(np.percentile(err, 95)), "max_m": float(err.max())}


def latest_before(t_pos: np.ndarray, t_sp: np.ndarray, i_pos: np.ndarray | None = None,
                  i_sp: np.ndarray | None = None) -> np.ndarray:
    """Index into ``t_sp`` of the latest setpoint logged before each sample, -1 if none.

    Both series sorted by time. Equal times are ordered by file position (``i_*``, packet indices) when
    given (a setpoint logged after the sample in the same microsecond does not count), else count as before.
    """
    if i_pos is None or i_sp is None:
        return np.searchsorted(t_sp, t_pos, side="right") - 1
    t = np.concatenate([t_sp, t_pos])
    i = np.concatenate([i_sp, i_pos])
    is_sp = np.concatenate([np.ones(t_sp.size, dtype=bool), np.zeros(t_pos.size, dtype=bool)])
    order = np.lexsort((i, t))
    counter = np.cumsum(is_sp[order]) - 1
    k = np.empty(t_pos.size, dtype=np.int64)
    k[order[~is_sp[order]] - t_sp.size] = counter[~is_sp[order]]
    return k


def tracking_stats(t_pos: np.ndarray, pos: np.ndarray, t_sp: np.ndarray, sp: np.ndarray,
                   mask: np.ndarray | None = None, i_pos: np.ndarray | None = None,
                   i_sp: np.ndarray | None = None) -> tuple[dict[str, Any], np.ndarray, np.ndarray]:
    """Error of each position sample against the latest setpoint logged before it (see latest_before).

    Returns (stats, sample times used, 3-D error per sample); ``t_*`` in integer µs, sorted.
    """
    if t_pos.size == 0 or t_sp.size == 0:
        return {"n_samples": 0}, np.zeros(0), np.zeros(0)
    k = latest_before(t_pos, t_sp, i_pos, i_sp)
    use = k >= 0
    if mask is not None:
        use &= mask
    d = pos[use] - sp[k[use]]
    e3 = np.linalg.norm(d, axis=1)
    out = error_stats(e3)
    if e3.size:
        out["horizontal"] = error_stats(np.linalg.norm(d[:, :2], axis=1))
        out["vertical"] = error_stats(np.abs(d[:, 2]))
    return out, t_pos[use], e3
