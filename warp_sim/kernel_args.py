"""Kernel arguments grouped into Warp structs, and the struct instances built once and kept.

A kernel that reads most of the Model and both states took up to 80 parameters, one per array:
every launch packed them all, and every signature and call site spelled them out.  The arrays
travel instead in structs named after what they hold, whose fields are named exactly like the
Model / State / Contacts attributes they come from (tests/test_architecture.py checks it), so
``model.body_inv_mass[i]`` in a kernel is ``Model.body_inv_mass``.

``bind`` keeps one instance per owner (a State, the Model, a Contacts, a solver) and struct
type, and builds a new one only when one of its source attributes was replaced (a buffer that
grew): the recorded launches of launch.py compare arguments by identity, so an unchanged
instance costs nothing to pass, and a new one is re-set like any changed argument.  An instance
is never changed in place: a recorded launch holds a packed copy of it.  The two state buffers
swap every step; each State keeps its own instance, so the struct passed as ``state_in`` is
always the buffer being read.
"""

from __future__ import annotations

import weakref

import warp as wp

_bound: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # owner -> {struct: (values, instance)}
_names: dict = {}  # struct -> field names


@wp.struct
class BodyModel:
    """The Model's per-body arrays (and the checkpoints' body-frame points)."""

    # Model
    body_shape: wp.array(dtype=wp.int32)
    body_size: wp.array(dtype=wp.vec3)
    body_inv_mass: wp.array(dtype=float)
    body_inertia: wp.array(dtype=wp.vec3)
    body_inv_inertia: wp.array(dtype=wp.vec3)
    body_friction: wp.array(dtype=float)
    body_restitution: wp.array(dtype=float)
    body_rolling_resistance: wp.array(dtype=float)
    body_rolling_arm: wp.array(dtype=float)
    body_sphere_radius: wp.array(dtype=float)
    body_covered_faces: wp.array(dtype=wp.int32)  # collide/covered_faces.py
    body_checkpoint_start: wp.array(dtype=wp.int32)
    body_checkpoint_count: wp.array(dtype=wp.int32)
    checkpoint_local: wp.array(dtype=wp.vec3)
    body_checkpoint_cell: wp.array(dtype=wp.vec3)  # collide/face_search.py


@wp.struct
class TerrainModel:
    """The Model's flat terrain description (terrain.py)."""

    # Model
    terrain_kind: int
    terrain_coef: wp.array(dtype=wp.vec2)
    terrain_terms: int
    terrain_frequency: float
    terrain_scale: wp.vec3
    terrain_offset: wp.vec3
    terrain_plane: wp.vec4
    terrain_slope_bound: float
    terrain_curvature_bound: float
    terrain_cubic_bound: float
    terrain_quartic_bound: float


@wp.struct
class BodyState:
    """One State buffer."""

    # State in/out
    body_pos: wp.array(dtype=wp.vec3)
    body_quat: wp.array(dtype=wp.quat)
    body_rot: wp.array(dtype=wp.mat33)
    body_vel: wp.array(dtype=wp.vec3)
    body_angmom: wp.array(dtype=wp.vec3)


@wp.struct
class TerrainContacts:
    """The terrain contact slots of a Contacts."""

    # Contacts in/out
    terrain_contact_active: wp.array(dtype=wp.int32)
    terrain_contact_point: wp.array(dtype=wp.vec3)
    terrain_contact_normal: wp.array(dtype=wp.vec3)
    terrain_contact_depth: wp.array(dtype=float)
    terrain_contact_normal_impulse: wp.array(dtype=float)
    terrain_contact_tangent_impulse: wp.array(dtype=wp.vec3)
    terrain_contact_surface: wp.array(dtype=wp.vec2)
    terrain_contact_count: wp.array(dtype=wp.int32)
    # per body: the pose its slots were last found at (collide/still_contacts.py)
    terrain_contact_anchor_pos: wp.array(dtype=wp.vec3)
    terrain_contact_anchor_quat: wp.array(dtype=wp.quat)


@wp.struct
class PairContacts:
    """The body-body pairs of a Contacts, as the solver reads them."""

    # Contacts in/out
    pair_body: wp.array(dtype=wp.vec2i)
    pair_point_count: wp.array(dtype=wp.int32)
    pair_normal: wp.array(dtype=wp.vec3)
    pair_point: wp.array(dtype=wp.vec3)
    pair_depth: wp.array(dtype=float)
    pair_feature: wp.array(dtype=wp.int32)
    pair_normal_impulse: wp.array(dtype=float)
    pair_tangent_impulse: wp.array(dtype=wp.vec3)
    pair_relax_chain: wp.array(dtype=wp.int32)
    pair_passes_clear: wp.array(dtype=wp.int32)
    pair_twist: wp.array(dtype=wp.vec4)  # the points' patch: centre, friction arm scale (collide/contact_patch.py)


@wp.struct
class BadSteps:
    """Where the non-finite check records the first bad step of each body."""

    # Out
    sim_step: wp.array(dtype=wp.int32)
    body_bad_step: wp.array(dtype=wp.int32)
    bad_count: wp.array(dtype=wp.int32)


def bind(struct, owner, *sources, **values):
    """``owner``'s instance of ``struct``, its fields taken from ``values`` or else from the first
    source with that attribute; rebuilt only when a field's value is no longer the same object."""
    names = _names.get(struct)
    if names is None:
        names = _names[struct] = list(struct.vars)
    current = tuple(values[n] if n in values else _attribute(n, sources) for n in names)
    cache = _bound.get(owner)
    if cache is None:
        cache = _bound[owner] = {}
    entry = cache.get(struct)
    if entry is not None and all(a is b for a, b in zip(entry[0], current)):
        return entry[1]
    instance = struct()
    for name, value in zip(names, current):
        setattr(instance, name, value)
    cache[struct] = (current, instance)
    return instance


def _attribute(name: str, sources):
    for source in sources:
        value = getattr(source, name, None)
        if value is not None:
            return value
    raise AttributeError(f"no source holds {name!r}")
