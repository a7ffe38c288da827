"""ModelBuilder: collects bodies on the host, then uploads one static Model."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .model import Model
from .terrain import NoTerrain, PlaneTerrain, Terrain
from .types import FRICTION_MODELS, FRICTION_SLIPPERINESS, SHAPE_BOX, SHAPE_SPHERE


@dataclass
class Material:
    """Contact material. ``friction`` is Coulomb mu; under ``friction_model = "slipperiness"``
    the thesis's gamma in [0, 1] is used instead: the friction impulse is clamped to (1 - gamma)
    times the normal impulse (SEED.md 3), which is Coulomb friction with mu = 1 - gamma."""

    restitution: float = 0.0
    friction: float = 0.5
    friction_model: str = "coulomb"
    slipperiness: float = 0.5
    rolling_resistance: float = 0.0

    def effective_friction(self) -> float:
        if FRICTION_MODELS[self.friction_model] == FRICTION_SLIPPERINESS:
            return 1.0 - self.slipperiness
        return self.friction


def quat_to_matrix(q) -> np.ndarray:
    x, y, z, w = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def box_checkpoints(half_extents, per_edge: int) -> np.ndarray:
    """Points on the box surface: an even per_edge^3 lattice, keeping those on a face.

    per_edge = 2 gives the 8 corners (exact against a plane, where the deepest point of a box
    is always a corner); 3 adds edge midpoints and face centres (26 points), and so on.  The
    spacing must stay below the terrain's feature size for the thesis's method to be accurate.
    """
    t = np.linspace(-1.0, 1.0, per_edge)
    g = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    on_surface = np.any(np.abs(g) == 1.0, axis=1)
    return g[on_surface] * np.asarray(half_extents, dtype=np.float64)


class ModelBuilder:
    """Adds spheres and boxes, sets the terrain, then ``finalize`` uploads a Model."""

    def __init__(self, material: Material | None = None):
        self.material = material or Material()
        self.terrain: Terrain = NoTerrain()
        self.bodies: list[dict] = []

    def set_terrain(self, terrain: Terrain):
        self.terrain = terrain

    def _add(self, shape, size, mass, position, orientation, velocity, angular_velocity,
             restitution, friction, static):
        index = len(self.bodies)
        self.bodies.append(
            dict(
                shape=shape,
                size=np.asarray(size, dtype=np.float64),
                mass=float(mass),
                position=np.asarray(position, dtype=np.float64),
                orientation=np.asarray(orientation, dtype=np.float64),
                velocity=np.asarray(velocity, dtype=np.float64),
                angular_velocity=np.asarray(angular_velocity, dtype=np.float64),
                restitution=self.material.restitution if restitution is None else float(restitution),
                friction=self.material.effective_friction() if friction is None else float(friction),
                static=bool(static),
            )
        )
        return index

    def add_sphere(self, radius, mass=1.0, position=(0, 0, 0), orientation=(0, 0, 0, 1),
                   velocity=(0, 0, 0), angular_velocity=(0, 0, 0), restitution=None, friction=None,
                   static=False) -> int:
        return self._add(SHAPE_SPHERE, (radius, 0.0, 0.0), mass, position, orientation, velocity,
                         angular_velocity, restitution, friction, static)

    def add_box(self, half_extents, mass=1.0, position=(0, 0, 0), orientation=(0, 0, 0, 1),
                velocity=(0, 0, 0), angular_velocity=(0, 0, 0), restitution=None, friction=None,
                static=False) -> int:
        return self._add(SHAPE_BOX, half_extents, mass, position, orientation, velocity,
                         angular_velocity, restitution, friction, static)

    def default_checkpoints_per_edge(self) -> int:
        # On a plane the corners are exact; curved terrain needs points between them.
        return 2 if isinstance(self.terrain, PlaneTerrain) else 3

    def finalize(self, device="cpu", checkpoints_per_edge: int | None = None) -> Model:
        per_edge = checkpoints_per_edge or self.default_checkpoints_per_edge()
        n = len(self.bodies)
        h = {
            "body_shape": np.zeros(n, np.int32),
            "body_size": np.zeros((n, 3), np.float32),
            "body_bound_radius": np.zeros(n, np.float32),
            "body_inv_mass": np.zeros(n, np.float32),
            "body_inertia": np.zeros((n, 3), np.float32),
            "body_inv_inertia": np.zeros((n, 3), np.float32),
            "body_restitution": np.zeros(n, np.float32),
            "body_friction": np.zeros(n, np.float32),
            "body_rolling_resistance": np.full(n, self.material.rolling_resistance, np.float32),
            "body_checkpoint_start": np.zeros(n, np.int32),
            "body_checkpoint_count": np.zeros(n, np.int32),
            "body_pos": np.zeros((n, 3), np.float32),
            "body_quat": np.zeros((n, 4), np.float32),
            "body_rot": np.zeros((n, 3, 3), np.float32),
            "body_vel": np.zeros((n, 3), np.float32),
            "body_angmom": np.zeros((n, 3), np.float32),
        }
        box_points_cache: dict[tuple, np.ndarray] = {}
        checkpoint_body, checkpoint_local = [], []
        for i, b in enumerate(self.bodies):
            m = b["mass"]
            if b["shape"] == SHAPE_SPHERE:
                r = b["size"][0]
                inertia = np.full(3, 0.4 * m * r * r)
                bound = r
                points = np.zeros((1, 3))
            else:
                inertia = inertia_box(m, b["size"])
                bound = float(np.linalg.norm(b["size"]))
                key = tuple(b["size"])
                if key not in box_points_cache:
                    box_points_cache[key] = box_checkpoints(b["size"], per_edge)
                points = box_points_cache[key]
            q = b["orientation"] / np.linalg.norm(b["orientation"])
            rot = quat_to_matrix(q)
            h["body_shape"][i] = b["shape"]
            h["body_size"][i] = b["size"]
            h["body_bound_radius"][i] = bound
            h["body_restitution"][i] = b["restitution"]
            h["body_friction"][i] = b["friction"]
            h["body_inertia"][i] = inertia
            if not b["static"]:
                h["body_inv_mass"][i] = 1.0 / m
                h["body_inv_inertia"][i] = 1.0 / inertia
                # L = R I_body R^T omega
                h["body_angmom"][i] = rot @ (inertia * (rot.T @ b["angular_velocity"]))
                h["body_vel"][i] = b["velocity"]
            h["body_pos"][i] = b["position"]
            h["body_quat"][i] = q
            h["body_rot"][i] = rot
            h["body_checkpoint_start"][i] = len(checkpoint_body)
            h["body_checkpoint_count"][i] = len(points)
            checkpoint_body.extend([i] * len(points))
            checkpoint_local.append(points)
        h["checkpoint_body"] = np.asarray(checkpoint_body, np.int32)
        h["checkpoint_local"] = (
            np.concatenate(checkpoint_local).astype(np.float32) if checkpoint_local else np.zeros((0, 3), np.float32)
        )
        h["checkpoints_per_edge"] = per_edge
        return Model(h, self.terrain, device)


def inertia_box(mass: float, half_extents) -> np.ndarray:
    w, hgt, l = 2.0 * np.asarray(half_extents, dtype=np.float64)
    return mass / 12.0 * np.array([hgt * hgt + l * l, w * w + l * l, w * w + hgt * hgt])


def random_quaternions(rng: np.random.Generator, count: int) -> np.ndarray:
    """Uniform random rotations (Shoemake), (x, y, z, w)."""
    u1, u2, u3 = rng.random((3, count))
    a, b = np.sqrt(1 - u1), np.sqrt(u1)
    return np.stack(
        [a * np.sin(2 * math.pi * u2), a * np.cos(2 * math.pi * u2), b * np.sin(2 * math.pi * u3),
         b * np.cos(2 * math.pi * u3)], axis=1)
