"""Per-body dynamic state (SEED.md 2: S = (x, R, P, L)), double-buffered by the Simulator."""

from __future__ import annotations

import numpy as np
import warp as wp


class State:
    """Body state arrays, all of length ``body_count``.

    Attributes:
        body_pos: centre-of-mass position [m], vec3.
        body_quat: orientation quaternion (x, y, z, w); the integrated variable in ``quaternion`` mode.
        body_rot: orientation matrix (columns are the body axes in world); the integrated variable
            in the ``matrix*`` modes, where it may drift from orthonormal (``matrix``) by design.
        body_vel: linear velocity [m/s] (P = m v).
        body_angmom: angular momentum L in world frame [kg m^2/s]; omega = R I_body^-1 R^T L.
    """

    def __init__(self, body_count: int, device):
        self.body_count = body_count
        self.body_pos = wp.zeros(body_count, dtype=wp.vec3, device=device)
        self.body_quat = wp.zeros(body_count, dtype=wp.quat, device=device)
        self.body_rot = wp.zeros(body_count, dtype=wp.mat33, device=device)
        self.body_vel = wp.zeros(body_count, dtype=wp.vec3, device=device)
        self.body_angmom = wp.zeros(body_count, dtype=wp.vec3, device=device)

    def fields(self):
        return (self.body_pos, self.body_quat, self.body_rot, self.body_vel, self.body_angmom)

    def assign(self, other: "State"):
        for dst, src in zip(self.fields(), other.fields()):
            wp.copy(dst, src)

    def to_numpy(self) -> dict[str, np.ndarray]:
        return {
            "position": self.body_pos.numpy(),
            "orientation": self.body_quat.numpy(),
            "rotation_matrix": self.body_rot.numpy(),
            "velocity": self.body_vel.numpy(),
            "angular_momentum": self.body_angmom.numpy(),
        }
