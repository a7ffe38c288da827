"""Sleeping: bodies at rest stop being integrated and solved until something touches them.

Box2D v3 puts whole islands to sleep.  Here the same rule is reached without building islands:

* each dynamic body keeps a timer that grows while its fastest point moves slower than
  ``sleep_velocity`` (|v| + |w| r_bound, Box2D's measure) and resets otherwise;
* the timer also resets while that speed has risen in every step for ``sleep_time / 2`` or
  longer, each step by at least ``a_rise dt`` with a_rise = SLEEP_RISE_FRACTION sleep_velocity /
  sleep_time: a body starting from rest down a shallow incline is accelerating, not settling.
  On the speed alone it fell asleep below a = sleep_velocity / sleep_time (0.1 m/s^2 at the
  defaults: a ball rolling down a 0.3 degree slope, a = 0.037 m/s^2, slept after 4.6 mm).  A
  settling body's speed falls or jitters; it does not rise for 15 steps running.  What is left:
  bodies accelerating under a_rise (0.01 m/s^2 at the defaults) still fall asleep;
* the speed is that of the velocity the last contact solve left: the stored velocity less the
  substep's closing kick (1 - alpha) g h (integrate.py), which a resting body's contacts take back
  only at the next substep.  Taken whole, a box resting on the plane moved at g h / 2 under
  ``verlet`` and ``rk4`` (g h under ``explicit_euler``), 0.082 m/s at dt 1/60 with one substep,
  and never slept;
* nothing sleeps where gravity is weaker than a_rise (zero gravity): a slow body is then told from
  a resting one by nothing the timers see, and a free body drifting at 0.049 m/s fell asleep
  after sleep_time, its momentum zeroed (two touching cubes drifting together alike).  Under
  gravity a body no contact holds accelerates at g and the rise rule keeps it awake; one sliding
  slower than sleep_velocity on a frictionless surface is still taken for resting (left);
* a body sleeps when its own timer and those of all the dynamic bodies it touches have passed
  ``sleep_time``; so a pile sleeps when all of it has been still, as an island would;
* a sleeping body that touches a body whose timer is short wakes up with its timer reset, and
  the wake spreads one contact per step through the pile.

A sleeping body counts as static for the rest of the pipeline (inverse mass 0 in the arrays the
kernels read), so terrain contact, broad phase, narrow phase and solver all skip it: that is
where the saving comes from.  Its velocity is zeroed when it falls asleep.

* a sleeping body that an awake one touches wakes before the solve of that same step, and so
  does every sleeper that touches it, and so on (Box2D wakes an island when one of its contacts
  begins touching): the pairs are found, the touched sleepers marked and woken, and the collision
  pass is run again, so the woken bodies' terrain contacts and their pairs with other sleepers
  take part in the step; the sleepers those pairs reach are woken in turn, until a pass wakes
  nobody (a device flag, ``wp.capture_while``: no host read).  So the extra passes run only in
  steps where something woke, one per contact of the deepest chain the wake crosses.  When only
  the touched sleepers woke and their sleeping neighbours acted as static for that step, a ball
  at 3 m/s (e = 1) striking a sleeping row of four touching balls bounced back off it at 3 m/s,
  the momentum reversed.

Neighbour timers come from the last substep's contact pairs, one thread per pair, the minimum
taken with atomics (the same result whatever the order; on the CPU these launches run whole on
one thread, as Warp's CPU atomics are not atomic across threads).
"""

from __future__ import annotations

import numpy as np
import warp as wp

from .launch import gpu_blocks, launch

wp.set_module_options({"enable_backward": False})

NO_NEIGHBOUR = 1.0e30
# the smallest steady acceleration kept awake, as a fraction of sleep_velocity / sleep_time: small
# enough to move the blind spot ten times lower, large enough that float32 noise in a resting
# body's speed (1e-6 m/s) never reads as a rise
SLEEP_RISE_FRACTION = 0.1


@wp.kernel
def gather_neighbour_timers(
    tid_offset: int,
    # Contacts in
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    # Model
    body_inv_mass: wp.array(dtype=float),
    # Sleep in/out
    body_sleep_timer: wp.array(dtype=float),
    body_neighbour_timer: wp.array(dtype=float),
):
    """One thread per pair slot (past the live count: return).  The minimum is taken with
    atomics: its result does not depend on the order the threads arrive in."""
    p = wp.tid() + tid_offset
    if p >= pair_count[0] or pair_point_count[p] == 0:
        return
    ij = pair_body[p]
    i = ij[0]
    j = ij[1]
    if body_inv_mass[j] > 0.0:
        wp.atomic_min(body_neighbour_timer, i, body_sleep_timer[j])
    if body_inv_mass[i] > 0.0:
        wp.atomic_min(body_neighbour_timer, j, body_sleep_timer[i])


@wp.kernel
def mark_touched_sleepers(
    tid_offset: int,
    # Contacts in
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    # Model
    body_inv_mass: wp.array(dtype=float),
    # Settings
    sleep_time: float,
    # Sleep in
    body_inv_mass_awake: wp.array(dtype=float),
    body_sleep_timer: wp.array(dtype=float),
    # Out
    body_wake: wp.array(dtype=wp.int32),
    woken: wp.array(dtype=wp.int32),
):
    """A sleeping body in a pair with an awake dynamic body that is moving (its timer short of
    sleep_time: the same test as the neighbour rule of update_sleep, so a pile falling asleep body
    by body is not woken by its own still members) is to wake before this step's solve.  Reads
    only the state of the step's start, writes by atomic max: race-free."""
    p = wp.tid() + tid_offset
    if p >= pair_count[0] or pair_point_count[p] == 0:
        return
    ij = pair_body[p]
    for side in range(2):
        b = ij[side]
        other = ij[1 - side]
        moving = body_inv_mass_awake[other] > 0.0 and body_sleep_timer[other] < sleep_time
        if body_inv_mass[b] > 0.0 and body_inv_mass_awake[b] == 0.0 and moving:
            wp.atomic_max(body_wake, b, 1)
            wp.atomic_max(woken, 0, 1)


@wp.kernel
def wake_marked(
    tid_offset: int,
    body_inv_mass: wp.array(dtype=float),
    body_wake: wp.array(dtype=wp.int32),
    body_sleep_timer: wp.array(dtype=float),
    body_inv_mass_awake: wp.array(dtype=float),
):
    i = wp.tid() + tid_offset
    if body_wake[i] != 0:
        body_wake[i] = 0
        body_sleep_timer[i] = 0.0
        body_inv_mass_awake[i] = body_inv_mass[i]


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
    sleep_rise_step: float,
    settle: int,
    closing_kick: wp.vec3,
    # State in/out
    body_rot: wp.array(dtype=wp.mat33),
    body_vel: wp.array(dtype=wp.vec3),
    body_angmom: wp.array(dtype=wp.vec3),
    # Sleep in/out
    body_sleep_timer: wp.array(dtype=float),
    body_sleep_speed: wp.array(dtype=float),
    body_sleep_rise: wp.array(dtype=float),
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
    # a sleeper is not integrated: no kick was added to its (zeroed) velocity
    kick = wp.where(body_inv_mass_awake[i] == 0.0, wp.vec3(0.0), closing_kick)
    speed = wp.length(body_vel[i] - kick) + wp.length(omega) * body_bound_radius[i]
    rise = 0.0
    if speed > body_sleep_speed[i] + sleep_rise_step:
        rise = body_sleep_rise[i] + dt
    body_sleep_speed[i] = speed
    body_sleep_rise[i] = rise
    timer = body_sleep_timer[i]
    if settle != 0 and speed < sleep_velocity and rise < 0.5 * sleep_time:
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
    def __init__(self, model, sleep_velocity: float, sleep_time: float, device, gravity_magnitude: float,
                 closing_kick: tuple):
        """``closing_kick``: (1 - alpha) g h, the gravity the integrator adds after the substep's
        solve (module docstring)."""
        self.model = model
        self.device = device
        self.sleep_velocity = sleep_velocity
        self.sleep_time = sleep_time
        self.gravity_magnitude = gravity_magnitude
        self.closing_kick = tuple(closing_kick)
        n = max(model.body_count, 1)
        self.body_sleep_timer = wp.zeros(n, dtype=float, device=device)
        self.body_sleep_speed = wp.zeros(n, dtype=float, device=device)  # the speed of the last update
        self.body_sleep_rise = wp.zeros(n, dtype=float, device=device)  # how long that speed has risen
        self.body_neighbour_timer = wp.full(n, NO_NEIGHBOUR, dtype=float, device=device)
        self.body_inv_mass_awake = wp.clone(model.body_inv_mass)
        self.body_wake = wp.zeros(n, dtype=wp.int32, device=device)
        self.woken = wp.zeros(1, dtype=wp.int32, device=device)

    def wake_touched(self, contacts, recollide):
        """Before the solve: wake the sleepers that an awake body touches and, while any woke, run
        ``recollide()`` (the collision pass again, now with them awake) and wake the sleepers those
        touch, so a blow meets the whole sleeping island it reaches (module docstring)."""
        if contacts.pair_max == 0:
            return
        self._wake_round(contacts)
        wp.capture_while(self.woken, self._recollide_and_wake, contacts=contacts, recollide=recollide)

    def _wake_round(self, contacts):
        m = self.model
        self.woken.zero_()
        # atomics: one launch, never split into CPU chunks (launch.py: Warp's CPU atomics are plain
        # read-modify-writes, so chunks on two threads would race)
        wp.launch(mark_touched_sleepers, dim=contacts.pair_max, device=self.device, **gpu_blocks(self.device), inputs=[
            0, contacts.pair_count, contacts.pair_body, contacts.pair_point_count, m.body_inv_mass, self.sleep_time,
            self.body_inv_mass_awake, self.body_sleep_timer, self.body_wake, self.woken])
        launch(wake_marked, m.body_count, key=self, inputs=[
            m.body_inv_mass, self.body_wake, self.body_sleep_timer, self.body_inv_mass_awake], device=self.device)

    def _recollide_and_wake(self, contacts, recollide):
        recollide()
        self._wake_round(contacts)

    def update(self, state, dt: float, contacts=None):
        """After a step: gather neighbour timers over the contact pairs, then decide per body."""
        m = self.model
        if contacts is not None and contacts.pair_max > 0:
            wp.launch(gather_neighbour_timers, dim=contacts.pair_max, device=self.device, **gpu_blocks(self.device), inputs=[
                0, contacts.pair_count, contacts.pair_body, contacts.pair_point_count, m.body_inv_mass,
                self.body_sleep_timer, self.body_neighbour_timer])  # atomics: never split (see above)
        launch(update_sleep, m.body_count, key=self, inputs=[
            m.body_inv_mass, m.body_inv_inertia, m.body_bound_radius, dt, self.sleep_velocity, self.sleep_time,
            self.rise_acceleration() * dt, int(self.gravity_magnitude >= self.rise_acceleration()),
            wp.vec3(*self.closing_kick), state.body_rot,
            state.body_vel, state.body_angmom, self.body_sleep_timer, self.body_sleep_speed, self.body_sleep_rise,
            self.body_neighbour_timer, self.body_inv_mass_awake], device=self.device)

    def rise_acceleration(self) -> float:
        """a_rise: the smallest steady acceleration the rise rule keeps awake (module docstring)."""
        return SLEEP_RISE_FRACTION * self.sleep_velocity / self.sleep_time

    def wake_all(self):
        self.body_sleep_timer.zero_()
        self.body_sleep_rise.zero_()
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
