"""Pinhole camera, body mount, and NED body pose -> OpenCV world-to-camera extrinsics.

Conventions: world NED, body FRD, quaternions (w, x, y, z) rotating body -> world. The camera frame is
OpenCV (x right, y down, z forward). With the default mount the optical axis is body +x, image right is
body +y and image down is body +z. A point X_w (world) maps to X_c = R @ X_w + t.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

DEFAULT_VFOV_RAD = math.radians(75.0)
# OpenCV camera axes expressed from a forward-right-down frame: cv = P @ frd
_P_CV_FROM_FRD = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])


def quat_to_matrix(q: tuple[float, float, float, float] | np.ndarray) -> np.ndarray:
    """Rotation matrix of a (w, x, y, z) quaternion (normalised here)."""
    w, x, y, z = (float(v) for v in q)
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if n == 0.0:
        raise ValueError("zero quaternion")
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def matrix_to_quat(r: np.ndarray) -> np.ndarray:
    """(w, x, y, z) unit quaternion with w >= 0 of a rotation matrix."""
    r = np.asarray(r, float)
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    if tr > 0:
        s = math.sqrt(tr + 1.0) * 2
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2
        q = [(r[2, 1] - r[1, 2]) / s, 0.25 * s, (r[0, 1] + r[1, 0]) / s, (r[0, 2] + r[2, 0]) / s]
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2
        q = [(r[0, 2] - r[2, 0]) / s, (r[0, 1] + r[1, 0]) / s, 0.25 * s, (r[1, 2] + r[2, 1]) / s]
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2
        q = [(r[1, 0] - r[0, 1]) / s, (r[0, 2] + r[2, 0]) / s, (r[1, 2] + r[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def euler_to_quat(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    """(w, x, y, z) of the aerospace ZYX rotation (yaw, then pitch, then roll), body -> world."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy)


@dataclass(frozen=True)
class Pose:
    """NED body pose: position [m] and (w, x, y, z) quaternion rotating body -> world."""

    position: tuple[float, float, float] = (0.0, 0.0, -1.5)
    quat_wxyz: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)

    @staticmethod
    def of(pose: Pose | tuple | list) -> Pose:
        """Accept a Pose, (position, quat) or a bare position (level, facing +x)."""
        if isinstance(pose, Pose):
            return pose
        if len(pose) == 2 and len(pose[0]) == 3:
            return Pose(tuple(float(v) for v in pose[0]), tuple(float(v) for v in pose[1]))
        if len(pose) == 3:
            return Pose(tuple(float(v) for v in pose))
        raise ValueError(f"cannot interpret {pose!r} as a pose; pass Pose(position, quat_wxyz)")


START_POSE = Pose((0.0, 0.0, -1.5), (1.0, 0.0, 0.0, 0.0))


@dataclass(frozen=True)
class CameraMount:
    """Camera placement on the body: offset in body FRD [m] and roll/pitch/yaw [rad] of the camera's
    forward-right-down frame relative to body FRD (all zero: optical axis = body x)."""

    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def body_from_camera_frd(self) -> np.ndarray:
        return quat_to_matrix(euler_to_quat(*self.rpy))


@dataclass(frozen=True)
class PinholeCamera:
    """Pinhole intrinsics (square pixels) plus body mount. Principal point defaults to the image centre."""

    width: int = 320
    height: int = 240
    vfov_rad: float = DEFAULT_VFOV_RAD
    cx: float | None = None
    cy: float | None = None
    mount: CameraMount = field(default_factory=CameraMount)
    near: float = 0.05
    far: float = 100.0

    @property
    def fy(self) -> float:
        return (self.height / 2.0) / math.tan(self.vfov_rad / 2.0)

    @property
    def fx(self) -> float:
        return self.fy

    @property
    def principal_point(self) -> tuple[float, float]:
        return (self.width / 2.0 if self.cx is None else self.cx,
                self.height / 2.0 if self.cy is None else self.cy)

    @property
    def K(self) -> np.ndarray:
        px, py = self.principal_point
        return np.array([[self.fx, 0.0, px], [0.0, self.fy, py], [0.0, 0.0, 1.0]])

    def scaled(self, width: int, height: int) -> PinholeCamera:
        """Same field of view at another resolution."""
        return PinholeCamera(width, height, self.vfov_rad, None, None, self.mount, self.near, self.far)

    def world_to_camera(self, pose: Pose | tuple) -> tuple[np.ndarray, np.ndarray]:
        """(R, t) with X_c = R @ X_w + t for the camera on a body at ``pose``."""
        pose = Pose.of(pose)
        r_wb = quat_to_matrix(pose.quat_wxyz)
        r_w_cv = r_wb @ self.mount.body_from_camera_frd() @ _P_CV_FROM_FRD.T
        centre = np.asarray(pose.position, float) + r_wb @ np.asarray(self.mount.offset, float)
        r = r_w_cv.T
        return r, -r @ centre

    def camera_centre(self, pose: Pose | tuple) -> np.ndarray:
        r, t = self.world_to_camera(pose)
        return -r.T @ t

    def project(self, points_w: np.ndarray, pose: Pose | tuple) -> tuple[np.ndarray, np.ndarray]:
        """Project (N, 3) world points: (uv (N, 2) pixel coordinates, depth (N,) along the optical axis).

        Pixel centres are at integer + 0.5 (pixel (0, 0) covers [0, 1) x [0, 1))."""
        r, t = self.world_to_camera(pose)
        pc = np.asarray(points_w, float) @ r.T + t
        z = pc[:, 2]
        px, py = self.principal_point
        with np.errstate(divide="ignore", invalid="ignore"):
            uv = np.stack([self.fx * pc[:, 0] / z + px, self.fy * pc[:, 1] / z + py], axis=1)
        return uv, z
