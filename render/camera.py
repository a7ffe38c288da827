"""Fly and orbit camera; NumPy matrices (row-major here, transposed on upload to std140).

Angles: ``yaw`` turns about +y (0 looks down -z, positive turns towards +x), ``pitch`` looks up.
Fly mode moves the eye; orbit mode keeps the eye at ``distance`` behind ``target``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def perspective(fovy_deg: float, aspect: float, near: float, far: float) -> np.ndarray:
    f = 1.0 / math.tan(math.radians(fovy_deg) / 2.0)
    m = np.zeros((4, 4))
    m[0, 0] = f / max(aspect, 1e-6)
    m[1, 1] = f
    m[2, 2] = (far + near) / (near - far)
    m[2, 3] = 2.0 * far * near / (near - far)
    m[3, 2] = -1.0
    return m


def look_at(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    eye, target, up = (np.asarray(v, dtype=np.float64) for v in (eye, target, up))
    f = target - eye
    f /= np.linalg.norm(f)
    s = np.cross(f, up)
    if np.linalg.norm(s) < 1e-9:
        s = np.cross(f, (0.0, 0.0, 1.0))
    s /= np.linalg.norm(s)
    u = np.cross(s, f)
    m = np.identity(4)
    m[0, :3], m[1, :3], m[2, :3] = s, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


@dataclass
class Camera:
    mode: str = "fly"
    position: np.ndarray = field(default_factory=lambda: np.array([0.0, 5.0, 15.0]))
    yaw: float = 0.0
    pitch: float = -15.0
    fov: float = 55.0
    near: float = 0.05
    far: float = 2000.0
    speed: float = 8.0  # fly speed [m/s]
    target: np.ndarray = field(default_factory=lambda: np.zeros(3))
    distance: float = 20.0
    look_sensitivity: float = 0.2  # degrees per window unit of mouse motion

    def forward(self) -> np.ndarray:
        yaw, pitch = math.radians(self.yaw), math.radians(self.pitch)
        return np.array([math.sin(yaw) * math.cos(pitch), math.sin(pitch), -math.cos(yaw) * math.cos(pitch)])

    def right(self) -> np.ndarray:
        yaw = math.radians(self.yaw)
        return np.array([math.cos(yaw), 0.0, math.sin(yaw)])

    def eye(self) -> np.ndarray:
        if self.mode == "orbit":
            return self.target - self.forward() * self.distance
        return self.position.copy()

    def view_matrix(self) -> np.ndarray:
        eye = self.eye()
        return look_at(eye, eye + self.forward())

    def projection_matrix(self, aspect: float) -> np.ndarray:
        return perspective(self.fov, aspect, self.near, self.far)

    def view_projection(self, aspect: float) -> np.ndarray:
        return self.projection_matrix(aspect) @ self.view_matrix()

    def look_at(self, eye, target):
        """Place the eye and aim at target (orbit mode orbits that target)."""
        eye, target = np.asarray(eye, dtype=np.float64), np.asarray(target, dtype=np.float64)
        d = target - eye
        self.distance = float(np.linalg.norm(d)) or 1.0
        d /= self.distance
        self.pitch = math.degrees(math.asin(np.clip(d[1], -1.0, 1.0)))
        self.yaw = math.degrees(math.atan2(d[0], -d[2]))
        self.position = eye.copy()
        self.target = target.copy()

    def frame_bounds(self, lo, hi):
        """Look at an axis-aligned box from above and in front, so all of it is in view."""
        lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
        center = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 2.0)
        dist = radius / math.sin(math.radians(self.fov) / 2.0)
        direction = np.array([0.45, 0.55, 0.70])
        self.look_at(center + direction / np.linalg.norm(direction) * dist, center)
        self.speed = max(2.0, radius)

    def set_mode(self, mode: str):
        """Switch fly <-> orbit keeping the current view."""
        if mode == self.mode:
            return
        if mode == "orbit":
            self.target = self.position + self.forward() * self.distance
        else:
            self.position = self.eye()
        self.mode = mode

    # Input ------------------------------------------------------------------------------------

    def move(self, forward: float, right: float, up: float, dt: float, boost: float = 1.0):
        """Fly: move the eye; orbit: move the target.  Arguments are -1..1 key axes."""
        step = self.speed * boost * dt
        flat = self.forward()
        delta = step * (forward * flat + right * self.right() + up * np.array([0.0, 1.0, 0.0]))
        if self.mode == "orbit":
            self.target = self.target + delta
        else:
            self.position = self.position + delta

    def rotate(self, dx: float, dy: float):
        """Mouse look / orbit by a cursor motion in window units."""
        self.yaw = (self.yaw + dx * self.look_sensitivity) % 360.0
        self.pitch = float(np.clip(self.pitch - dy * self.look_sensitivity, -89.0, 89.0))

    def scroll(self, dy: float):
        """Fly: scale the speed; orbit: zoom."""
        factor = 1.15 ** dy
        if self.mode == "orbit":
            self.distance = float(np.clip(self.distance / factor, 0.5, self.far * 0.5))
        else:
            self.speed = float(np.clip(self.speed * factor, 0.1, 500.0))

    def project(self, points, width: int, height: int) -> np.ndarray:
        """World points -> (x, y) pixel coordinates, top-left origin; NaN behind the eye."""
        p = np.atleast_2d(np.asarray(points, dtype=np.float64))
        clip = np.c_[p, np.ones(len(p))] @ self.view_projection(width / height).T
        w = clip[:, 3:4]
        ndc = np.where(w > 1e-9, clip[:, :3] / np.where(w > 1e-9, w, 1.0), np.nan)
        x = (ndc[:, 0] * 0.5 + 0.5) * width
        y = (1.0 - (ndc[:, 1] * 0.5 + 0.5)) * height
        return np.stack([x, y], axis=1)
