"""Sleeping: bodies at rest stop being integrated and solved until something touches them.

Box2D v3 puts whole islands to sleep.  Here the same rule is reached without building islands:

* each dynamic body keeps a timer that grows while its fastest point moves slower than
  ``sleep_velocity`` (|v| + |w| r_bound, Box2D's measure) and resets otherwise;
* a body sleeps when its own timer and those of all the dynamic bodies it touches have passed
  ``sleep_time``; so a pile sleeps when all of it has been still, as an island would;
* a sleeping body that touches a body whose timer is short wakes up with its timer reset, and
  the wake spreads one contact per step through the pile.

A sleeping body counts as static for the rest of the pipeline (inverse mass 0 in the arrays the
kernels read), so terrain contact, broad phase, narrow phase and solver all skip it: that is
where the saving comes from.  Its velocity is zeroed when it falls asleep.

Neighbour timers come from the last substep's contact pairs, gathered colour by colour, so no
two threads write one body.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .launch import launch
from .solvers.coloring import COLOR_COUNT, color_range

wp.set_module_options({"enable_backward": False})

NO_NEIGHBOUR = 1.0e30


@wp.kernel
def gather_neighbour_timers(
    tid_offset: int,
    color: int,
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    body_inv_mass: wp.array(dtype=float),
    body_sleep_timer: wp.array(dtype=float),
    body_neighbour_timer: wp.array(dtype=float),
):
    r = color_range(color, color_start, wp.tid() + tid_offset)
    for index in range(r[0], r[1]):
        p = color_pairs_sorted[index]
        if pair_point_count[p] > 0:
            ij = pair_body[p]
            i = ij[0]
            j = ij[1]
            if body_inv_mass[j] > 0.0:
                body_neighbour_timer[i] = wp.min(body_neighbour_timer[i], body_sleep_timer[j])
            if body_inv_mass[i] > 0.0:
                body_neighbour_timer[j] = wp.min(body_neighbour_timer[j], body_sleep_timer[i])


@wp.kernel
def update_sleep(
    tid_offset: int,
    # Model
    body_inv_mass: wp.array(dtype=float),
    body_inv_inertia: wp.array(dtype=wp.vec3),
    body_bound_radius: wp.array(dtype=float),
    # Settings
    dt: float,
    sleep_velocity: float,
    sleep_time: float,
    # State in/out
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    body_angmom: wp.array(dtype=wp.vec3),
    # Sleep in/out
    body_sleep_timer: wp.array(dtype=float),
    body_neighbour_timer: wp.array(dtype=float),
    # Out
    body_inv_mass_awake: wp.array(dtype=float),
):
    i = wp.tid() + tid_offset
    inv_mass = body_inv_mass[i]
    neighbour = body_neighbour_timer[i]
    body_neighbour_timer[i] = NO_NEIGHBOUR
    if inv_mass == 0.0:
        body_inv_mass_awake[i] = 0.0
        return
    rot = body_rot[i]
    omega = rot * wp.cw_mul(body_inv_inertia[i], wp.transpose(rot) * body_angmom[i])
    speed = wp.length(body_vel[i]) + wp.length(omega) * body_bound_radius[i]
    timer = body_sleep_timer[i]
    if speed < sleep_velocity:
        timer = timer + dt
    else:
        timer = 0.0
    asleep = body_inv_mass_awake[i] == 0.0
    if timer >= sleep_time and neighbour >= sleep_time:
        if not asleep:
            body_vel[i] = wp.vec3(0.0)
            body_angmom[i] = wp.vec3(0.0)
        body_inv_mass_awake[i] = 0.0
    else:
        if asleep:
            timer = 0.0  # woken: stay awake a while, and wake the neighbours through this timer
        body_inv_mass_awake[i] = inv_mass
    body_sleep_timer[i] = timer


class Sleep:
    def __init__(self, model, sleep_velocity: float, sleep_time: float, device):
        self.model = model
        self.device = device
        self.sleep_velocity = sleep_velocity
        self.sleep_time = sleep_time
        n = max(model.body_count, 1)
        self.body_sleep_timer = wp.zeros(n, dtype=float, device=device)
        self.body_neighbour_timer = wp.full(n, NO_NEIGHBOUR, dtype=float, device=device)
        self.body_inv_mass_awake = wp.clone(model.body_inv_mass)

    def update(self, state, dt: float, contacts=None, color_sizes=None):
        """After a step: gather neighbour timers over the contact pairs, then decide per body."""
        m = self.model
        if contacts is not None and color_sizes:
            for color, size in enumerate(color_sizes):
                if size:
                    launch(gather_neighbour_timers, 1 if color == COLOR_COUNT else size, key=self, inputs=[
                        color, contacts.color_start, contacts.color_pairs_sorted, contacts.pair_body,
                        contacts.pair_point_count, m.body_inv_mass, self.body_sleep_timer,
                        self.body_neighbour_timer], device=self.device)
        launch(update_sleep, m.body_count, key=self, inputs=[
            m.body_inv_mass, m.body_inv_inertia, m.body_bound_radius, dt, self.sleep_velocity, self.sleep_time,
            state.body_rot, state.body_vel, state.body_angmom, self.body_sleep_timer, self.body_neighbour_timer,
            self.body_inv_mass_awake], device=self.device)

    def wake_all(self):
        self.body_sleep_timer.zero_()
        wp.copy(self.body_inv_mass_awake, self.model.body_inv_mass)

    def awake_count(self) -> int:
        dynamic = self.model.host["body_inv_mass"] > 0
        return int(np.count_nonzero(self.body_inv_mass_awake.numpy()[: self.model.body_count][dynamic]))


class AwakeModel:
    """The model as the kernels should see it this step: sleeping bodies have inverse mass 0."""

    def __init__(self, model, body_inv_mass):
        self._model = model
        self.body_inv_mass = body_inv_mass

    def __getattr__(self, name):
        return getattr(self._model, name)
