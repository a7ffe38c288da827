"""The static part of a simulation: bodies, shapes, materials, checkpoints, terrain."""

from __future__ import annotations

import numpy as np
import warp as wp

from .contacts import Contacts
from .solvers.pair_solve import CHAIN_MASS_RATIO
from .state import State
from .terrain import Terrain, terrain_model_fields


class Model:
    """Static arrays read by every kernel; built by ``ModelBuilder.finalize``.

    Attributes (arrays of length ``body_count`` unless noted):
        body_shape: SHAPE_SPHERE or SHAPE_BOX.
        body_size: sphere (radius, 0, 0) or box half-extents [m].
        body_bound_radius: radius of the bounding sphere about the centre of mass [m].
        body_covered_faces: a static box's faces another static box covers (collide/covered_faces.py).
        body_inv_mass: 1/m [1/kg]; 0 for static bodies.
        body_inertia, body_inv_inertia: principal body-frame inertia and its inverse (diagonal,
            SEED.md 2: box M/12 (h^2+l^2, ...), sphere 2/5 M r^2); zero inverse for static bodies.
        body_restitution, body_friction, body_rolling_resistance: material per body; friction is
            the Coulomb mu actually used (1 - slipperiness under the thesis's friction model).
        body_checkpoint_start, body_checkpoint_count: the body's terrain contact slot range.
        checkpoint_body, checkpoint_local: per slot, its body and body-frame point [m].
        body_checkpoint_cell: a box's checkpoint spacing halved, per body axis [m] (0 for a sphere):
            the cell of its support face a checkpoint searches (collide/face_search.py).
        terrain_*: flat terrain description (see terrain.py).

    Bodies may be stored in another order than the scene's (``body_order``, body_order.py):
    ``body_scene_index`` (int64, on the host) gives for internal body i its scene index, and
    ``body_internal_index`` is its inverse.  Every array above, and the State's, is in internal
    order; ``to_scene_order`` turns a per-body array into scene order.  In the scene order both
    are ``arange(body_count)``.
    """

    def __init__(self, host: dict, terrain: Terrain, device, body_scene_index=None, body_order: str = "scene"):
        self.device = device
        self.terrain = terrain
        self.host = host
        self.body_count = len(host["body_shape"])
        self.checkpoint_count = len(host["checkpoint_body"])
        self.body_order = body_order
        self._scene_ordered = body_scene_index is None
        if body_scene_index is None:
            self.body_scene_index = np.arange(self.body_count, dtype=np.int64)
            self.body_internal_index = self.body_scene_index
        else:
            from .body_order import inverse_order

            self.body_scene_index = np.asarray(body_scene_index, dtype=np.int64)
            if self.body_scene_index.shape != (self.body_count,):
                raise ValueError(f"body_scene_index must have shape ({self.body_count},), "
                                 f"got {self.body_scene_index.shape}")
            self.body_internal_index = inverse_order(self.body_scene_index)

        def arr(name, dtype):
            return wp.array(host[name], dtype=dtype, device=device)

        self.body_shape = arr("body_shape", wp.int32)
        self.body_size = arr("body_size", wp.vec3)
        self.body_bound_radius = arr("body_bound_radius", float)
        # host arrays written before the masks existed (saved models, hand-built scenes) cover nothing
        host.setdefault("body_covered_faces", np.zeros(len(host["body_shape"]), np.int32))
        self.body_covered_faces = arr("body_covered_faces", wp.int32)
        self.body_inv_mass = arr("body_inv_mass", float)
        self.body_inertia = arr("body_inertia", wp.vec3)
        self.body_inv_inertia = arr("body_inv_inertia", wp.vec3)
        self.body_restitution = arr("body_restitution", float)
        self.body_friction = arr("body_friction", float)
        self.body_rolling_resistance = arr("body_rolling_resistance", float)
        # c_r r of a sphere (its rolling-resistance torque per unit normal impulse), 0 for a box
        rolling_arm = np.where(host["body_shape"] == 0, host["body_rolling_resistance"] * host["body_size"][:, 0], 0.0)
        self.body_rolling_arm = wp.array(rolling_arm.astype(np.float32), dtype=float, device=device)
        # a sphere's radius, 0 for a box: sphere pairs are solved on their line of centres (pair_geometry.py)
        sphere_radius = np.where(host["body_shape"] == 0, host["body_size"][:, 0], 0.0)
        self.body_sphere_radius = wp.array(sphere_radius.astype(np.float32), dtype=float, device=device)
        self.has_restitution = bool(np.any(host["body_restitution"] > 0.0))
        # dynamic masses 10-fold apart: the colour schedule then runs the heavy-on-light chain
        # passes (solvers/pair_solve.chain_pass, CHAIN_MASS_RATIO), which a scene without pays nothing for
        inv_mass = host["body_inv_mass"][host["body_inv_mass"] > 0.0]
        self.has_mass_ratio = bool(inv_mass.size and inv_mass.max() >= CHAIN_MASS_RATIO * inv_mass.min())
        self.body_checkpoint_start = arr("body_checkpoint_start", wp.int32)
        self.body_checkpoint_count = arr("body_checkpoint_count", wp.int32)
        self.checkpoint_body = arr("checkpoint_body", wp.int32)
        self.checkpoint_local = arr("checkpoint_local", wp.vec3)
        # a box checkpoint's cell: half its lattice spacing along each body axis (collide/face_search.py)
        per_edge = int(host.get("checkpoints_per_edge", 3))
        cell = np.where((host["body_shape"] == 0)[:, None], 0.0, host["body_size"] / max(per_edge - 1, 1))
        self.body_checkpoint_cell = wp.array(cell.astype(np.float32), dtype=wp.vec3, device=device)
        self.set_terrain(terrain)

    def set_terrain(self, terrain: Terrain):
        """Swap the terrain in place; used by the GUI so physics and drawing change together."""
        self.terrain = terrain
        fields = terrain_model_fields(terrain)
        self.terrain_kind = int(fields["terrain_kind"])
        self.terrain_coef = wp.array(fields["terrain_coef"], dtype=wp.vec2, device=self.device)
        self.terrain_terms = int(fields["terrain_terms"])
        self.terrain_frequency = float(fields["terrain_frequency"])
        self.terrain_scale = wp.vec3(*fields["terrain_scale"])
        self.terrain_offset = wp.vec3(*fields["terrain_offset"])
        self.terrain_plane = wp.vec4(*fields["terrain_plane"])
        self.terrain_slope_bound = float(fields["terrain_slope_bound"])
        self.terrain_curvature_bound = float(fields["terrain_curvature_bound"])
        self.terrain_cubic_bound = float(fields["terrain_cubic_bound"])
        self.terrain_quartic_bound = float(fields["terrain_quartic_bound"])

    def to_scene_order(self, values, axis: int = 0) -> np.ndarray:
        """A per-body array (NumPy, or a Warp array such as ``sim.state.body_pos``) in internal
        order, as a new NumPy array in scene order along ``axis`` (1 for frames x bodies):
        element s is scene body s.  Always a copy, in the scene order too: on the CPU ``.numpy()``
        is a view of the live state, which the next step overwrites."""
        if isinstance(values, wp.array):
            values = values.numpy()
        if self._scene_ordered:
            return np.array(values, copy=True)
        return np.take(values, self.body_internal_index, axis=axis)

    def from_scene_order(self, values, axis: int = 0) -> np.ndarray:
        """The inverse of ``to_scene_order``: a per-body array in scene order, in internal order
        (e.g. velocities to ``assign`` to ``sim.state.body_vel``)."""
        if self._scene_ordered:
            return np.array(values, copy=True)
        return np.take(values, self.body_scene_index, axis=axis)

    @property
    def body_mass(self) -> np.ndarray:
        inv = self.host["body_inv_mass"]
        return np.where(inv > 0, 1.0 / np.where(inv > 0, inv, 1.0), 0.0)

    def state(self) -> State:
        """A State holding the initial layout."""
        s = State(self.body_count, self.device)
        s.body_pos.assign(self.host["body_pos"])
        s.body_quat.assign(self.host["body_quat"])
        s.body_rot.assign(self.host["body_rot"])
        s.body_vel.assign(self.host["body_vel"])
        s.body_angmom.assign(self.host["body_angmom"])
        return s

    def contacts(self, pair_max: int = 0) -> Contacts:
        return Contacts(self.checkpoint_count, pair_max, self.device, self.body_count)
