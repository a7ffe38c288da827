"""The colour schedule's overflow set, solved in parallel by mass splitting.

A pair finds no colour when its two bodies already use all COLOR_COUNT colours between them: a
dynamic plank carrying 49 balls (tests/test_pair_overflow.py), a body at the bottom of a heap of
small ones.  Such pairs may share bodies, so they cannot be swept one pair a thread like a colour;
walking them in order on one thread would cost a GPU about a microsecond a pair.

Instead every overflow pair is swept at once against the velocities the colours left, each with
its bodies' masses split (Tonge, Benevolenski and Voroshilov 2012, "Mass splitting for jitter-free
parallel rigid body simulation"): a body in s overflow pairs takes part in each with s times its
inverse mass and inverse inertia, and its new velocity is the mean of what its s pairs computed,

    v = v0 + (1/s) sum_p (v_p - v0),   v_p - v0 = s M^-1 P_p   =>   v = v0 + M^-1 sum_p P_p,

so the velocity change is exactly the sum of the impulses the pairs stored: warm starts, the
accumulated impulses and momentum stay consistent, as in a Gauss-Seidel sweep.  It is a Jacobi
step on the split bodies, so it converges more slowly than a colour's sweep; the overflow set is a
last resort, and Simulator.step says once when a scene reaches it.

Which way pays depends on the device (SimConfig.overflow_pairs, "auto": split on CUDA, in order
on the CPU).  On a GPU a walk by one thread costs about a microsecond a pair in every pair stage
(400 pairs, 12 stages a step: some 5 ms a step), where the split sweeps take a few launches.  On
the CPU both run on one thread, and the walk is one Gauss-Seidel pass against eight Jacobi ones:
a plank under 64 balls, colour schedule, 34.8 steps/s in order against 27.5 split; under 400
balls 22.6 against 17.1, the deepest ball 2.4 mm into the plank against 4.3 mm (a resting
column's budget is 7.5 mm; one run each, back to back).  So the CPU walks them, and its tests ask for "split" to prove the
GPU's way.

The sum is taken in 32.32 fixed point with integer atomics, whose result does not depend on the
order the threads add in (float atomics would round differently run to run on a GPU), and applied
by one owner pair per body (its lowest pair index).  The impact stage (impact.py) is split the
same way, one split sweep per impact sweep: each pair's time-of-impact shift is summed like its
velocity change, and the owner stamps the body with the sweep.  Only the chain passes of
heavy-on-light pairs (pair_solve.chain_pair) in the overflow set are still walked in order by one
thread (they walk the lighter body's terrain contacts too).

A solve or relax stage runs OVERFLOW_ITERATIONS split sweeps (below says why).  Launches use
OVERFLOW_THREADS threads striding over the set.  A captured step holds them behind conditional
nodes (``wp.capture_if`` on a flag written each substep), so a step with no pair in the set pays
one one-thread launch a substep for it, which reads two colour starts.  On the CPU the kernels
with atomics (the count and the two split sweeps) are plain launches, one thread: Warp's CPU
atomics are not atomic across launch chunks (warp_sim/launch.py).
"""

import warp as wp

from ..kernel_args import BodyModel, PairContacts
from ..launch import gpu_blocks, launch
from ..schedule.coloring import COLOR_COUNT
from .impact import OTHER_EVENT, impact_pair_velocity, unchanged_since
from .pair_solve import MODE_IMPACT, MODE_WARM_START, read_pair_velocity, solve_pair_points
from .solver_args import SolverBodies, StepSettings

wp.set_module_options({"enable_backward": False})

OVERFLOW_THREADS = 65536  # enough to fill a GPU for any overflow set; each strides over the set
# Split sweeps per solve or relax stage (a warm start applies stored impulses, once).  One Jacobi
# step leaves part of a push-out speed that a colour's Gauss-Seidel sweep would have taken back,
# and a body split more ways needs more steps.  Balls striking a 5 kg plank without gravity
# (tests/test_pair_overflow.py), largest kinetic energy gain in a step: 64 balls, 7.3e-4 with 1
# sweep, 8.2e-5 with 2, 2.2e-8 with 4; 144 balls (the plank in 104 overflow pairs), 1.8e-6 with 4
# and 2.3e-7 with 8, where the slab schedule's Gauss-Seidel gives 2.2e-8 (float rounding).
OVERFLOW_ITERATIONS = 8
FIXED_POINT = 4294967296.0  # 2^32: velocity changes summed as integers of 2^-32 m/s (or rad/s)
NO_OWNER = 2147483647


@wp.func
def add_fixed(sums: wp.array(dtype=wp.int64), base: int, change: wp.vec3):
    for k in range(3):
        wp.atomic_add(sums, base + k, wp.int64(wp.round(change[k] * FIXED_POINT)))


@wp.func
def split_count(solver_overflow_split: wp.array(dtype=wp.int32), b: int) -> float:
    """How many ways body b is split (1 for a static body, which no pair counts)."""
    return float(wp.max(solver_overflow_split[b], 1))


@wp.func
def add_split_change(sums: wp.array(dtype=wp.int64), b: int, dv: wp.vec3, dw: wp.vec3, split: float):
    """Body b's share of one split pair's velocity change: the change over its split count."""
    add_fixed(sums, 6 * b, dv / split)
    add_fixed(sums, 6 * b + 3, dw / split)


@wp.func
def take_fixed(sums: wp.array(dtype=wp.int64), base: int) -> wp.vec3:
    out = wp.vec3(0.0)
    for k in range(3):
        out[k] = float(wp.float64(sums[base + k]) * wp.float64(1.0 / FIXED_POINT))
        sums[base + k] = wp.int64(0)
    return out


@wp.kernel
def overflow_present(color_start: wp.array(dtype=wp.int32), present: wp.array(dtype=wp.int32)):
    # one thread, two loads: the flag the stage's conditional node reads (O(1) whatever the scene)
    present[0] = wp.where(color_start[COLOR_COUNT + 1] > color_start[COLOR_COUNT], 1, 0)


@wp.kernel
def overflow_count(
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
    # Model
    body_inv_mass: wp.array(dtype=float),
    # Contacts in
    pair_body: wp.array(dtype=wp.vec2i),
    # Solver out
    solver_overflow_split: wp.array(dtype=wp.int32),
    solver_overflow_owner: wp.array(dtype=wp.int32),
):
    """Per dynamic body: how many overflow pairs it is in, and the lowest of their indices."""
    t = wp.tid()
    for index in range(color_start[COLOR_COUNT] + t, color_start[COLOR_COUNT + 1], OVERFLOW_THREADS):
        p = color_pairs_sorted[index]
        ij = pair_body[p]
        for side in range(2):
            b = ij[side]
            if body_inv_mass[b] > 0.0:
                wp.atomic_add(solver_overflow_split, b, 1)
                wp.atomic_min(solver_overflow_owner, b, p)


@wp.kernel
def overflow_pair_pass(
    mode: int,
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in/out
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    solver_overflow_split: wp.array(dtype=wp.int32),
    solver_overflow_velocity: wp.array(dtype=wp.int64),
):
    """Every overflow pair swept against the velocities before this launch, with split masses;
    each body's share of the change summed in solver_overflow_velocity (v, then w, 6 a body)."""
    t = wp.tid()
    for index in range(color_start[COLOR_COUNT] + t, color_start[COLOR_COUNT + 1], OVERFLOW_THREADS):
        p = color_pairs_sorted[index]
        ij = pairs.pair_body[p]
        i = ij[0]
        j = ij[1]
        split_i = split_count(solver_overflow_split, i)
        split_j = split_count(solver_overflow_split, j)
        vel = read_pair_velocity(solver, i, j)
        out = solve_pair_points(p, mode, model, settings, pairs, solver, vel,
                                split_i * model.body_inv_mass[i], split_j * model.body_inv_mass[j],
                                split_i * solver.solver_inv_inertia[i], split_j * solver.solver_inv_inertia[j])
        if model.body_inv_mass[i] > 0.0:
            add_split_change(solver_overflow_velocity, i, out.vi - vel.vi, out.wi - vel.wi, split_i)
        if model.body_inv_mass[j] > 0.0:
            add_split_change(solver_overflow_velocity, j, out.vj - vel.vj, out.wj - vel.wj, split_j)


@wp.kernel
def overflow_apply(
    tid_offset: int,
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
    # Contacts in
    pair_body: wp.array(dtype=wp.vec2i),
    # Solver in/out
    solver_overflow_owner: wp.array(dtype=wp.int32),
    solver_overflow_velocity: wp.array(dtype=wp.int64),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
):
    """Each body's summed change added by its owner pair alone (no two threads write a body)."""
    t = wp.tid() + tid_offset
    for index in range(color_start[COLOR_COUNT] + t, color_start[COLOR_COUNT + 1], OVERFLOW_THREADS):
        p = color_pairs_sorted[index]
        ij = pair_body[p]
        for side in range(2):
            b = ij[side]
            if solver_overflow_owner[b] == p:
                solver_v[b] = solver_v[b] + take_fixed(solver_overflow_velocity, 6 * b)
                solver_w[b] = solver_w[b] + take_fixed(solver_overflow_velocity, 6 * b + 3)


@wp.kernel
def overflow_impact_pass(
    impact_sweep: int,
    impact_since: int,
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    solver_overflow_split: wp.array(dtype=wp.int32),
    solver_overflow_velocity: wp.array(dtype=wp.int64),
    solver_overflow_shift: wp.array(dtype=wp.int64),
    solver_overflow_hit: wp.array(dtype=wp.int32),
):
    """One impact sweep of every overflow pair (impact.impact_pair's, with split masses): velocity
    changes and time-of-impact shifts summed per body, and per body 1 if a pair struck it.  Stamps are read as the
    sweep before left them and written by overflow_impact_apply.  Bodies struck here get the
    event partner OTHER_EVENT (in overflow_impact_apply): a split pair's impact is no one pair's."""
    t = wp.tid()
    for index in range(color_start[COLOR_COUNT] + t, color_start[COLOR_COUNT + 1], OVERFLOW_THREADS):
        p = color_pairs_sorted[index]
        ij = pairs.pair_body[p]
        i = ij[0]
        j = ij[1]
        inv_mi = model.body_inv_mass[i]
        inv_mj = model.body_inv_mass[j]
        stamps = solver.solver_impact_stamp
        skip = unchanged_since(stamps[i], impact_since) and unchanged_since(stamps[j], impact_since)
        if pairs.pair_point_count[p] == 0 or skip or (inv_mi == 0.0 and inv_mj == 0.0):
            continue
        split_i = split_count(solver_overflow_split, i)
        split_j = split_count(solver_overflow_split, j)
        vel = read_pair_velocity(solver, i, j)
        out = impact_pair_velocity(p, model, settings, pairs, solver, vel.vi, vel.wi, vel.vj, vel.wj, split_i * inv_mi,
                                   split_j * inv_mj, split_i * solver.solver_inv_inertia[i],
                                   split_j * solver.solver_inv_inertia[j])
        pairs.pair_passes_clear[p] = out.clear
        if out.hit == 0:
            continue
        if inv_mi > 0.0:
            add_split_change(solver_overflow_velocity, i, out.vi - vel.vi, out.wi - vel.wi, split_i)
            add_fixed(solver_overflow_shift, 3 * i, out.shift_i / split_i)
            wp.atomic_max(solver_overflow_hit, i, 1)
        if inv_mj > 0.0:
            add_split_change(solver_overflow_velocity, j, out.vj - vel.vj, out.wj - vel.wj, split_j)
            add_fixed(solver_overflow_shift, 3 * j, out.shift_j / split_j)
            wp.atomic_max(solver_overflow_hit, j, 1)


@wp.kernel
def overflow_impact_apply(
    tid_offset: int,
    impact_sweep: int,
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
    # Contacts in
    pair_body: wp.array(dtype=wp.vec2i),
    # Solver in/out
    solver_overflow_owner: wp.array(dtype=wp.int32),
    solver_overflow_velocity: wp.array(dtype=wp.int64),
    solver_overflow_shift: wp.array(dtype=wp.int64),
    solver_overflow_hit: wp.array(dtype=wp.int32),
    solver_v: wp.array(dtype=wp.vec3),
    solver_w: wp.array(dtype=wp.vec3),
    solver_toi_shift: wp.array(dtype=wp.vec3),
    solver_impact_stamp: wp.array(dtype=wp.int32),
    solver_event_partner: wp.array(dtype=wp.int32),
):
    """Each struck body's summed impact applied by its owner pair, as impact_pair writes one: the
    sweep's stamp, and the shift added to the body's; its event is no one pair's (OTHER_EVENT)."""
    t = wp.tid() + tid_offset
    for index in range(color_start[COLOR_COUNT] + t, color_start[COLOR_COUNT + 1], OVERFLOW_THREADS):
        p = color_pairs_sorted[index]
        ij = pair_body[p]
        for side in range(2):
            b = ij[side]
            if solver_overflow_owner[b] == p and solver_overflow_hit[b] != 0:
                solver_v[b] = solver_v[b] + take_fixed(solver_overflow_velocity, 6 * b)
                solver_w[b] = solver_w[b] + take_fixed(solver_overflow_velocity, 6 * b + 3)
                shift = take_fixed(solver_overflow_shift, 3 * b)
                solver_toi_shift[b] = solver_toi_shift[b] + shift
                solver_impact_stamp[b] = impact_sweep
                solver_event_partner[b] = OTHER_EVENT
                solver_overflow_hit[b] = 0


class OverflowPairs:
    """The scratch and launches of the overflow set's split sweeps (module docstring)."""

    def __init__(self, body_count: int, device):
        n = max(body_count, 1)
        self.device = device
        self.solver_overflow_split = wp.zeros(n, dtype=wp.int32, device=device)
        self.solver_overflow_owner = wp.full(n, NO_OWNER, dtype=wp.int32, device=device)
        self.solver_overflow_velocity = wp.zeros(6 * n, dtype=wp.int64, device=device)
        self.solver_overflow_shift = wp.zeros(3 * n, dtype=wp.int64, device=device)  # impacts' time-of-impact shifts
        self.solver_overflow_hit = wp.zeros(n, dtype=wp.int32, device=device)
        self.present = wp.zeros(1, dtype=wp.int32, device=device)  # 1 while the set holds a pair

    @staticmethod
    def threads(bucket_size: int) -> int:
        """Threads for a launch over the set: its size when read on the host (direct stepping),
        OVERFLOW_THREADS when it is a bound (capturable launches)."""
        return max(1, min(bucket_size, OVERFLOW_THREADS))

    def stage(self, mode: int, dim: int, recount: bool, contacts, body_inv_mass, model_args, settings_args,
              pairs_args, solver_args, solver_v, solver_w, impact_sweep: int = 0, impact_since: int = -1):
        """One pair stage over the set.  ``recount`` (the substep's first pair stage after a
        colouring: its first impact sweep, its warm start) finds whether the set holds any pair and,
        if so, its split counts and owners; every stage then runs only if it does
        (``wp.capture_if``: a conditional node in a captured graph, so a step whose colours hold
        every pair skips the set's launches at replay; read on the host otherwise)."""
        args = dict(mode=mode, dim=dim, recount=recount, contacts=contacts, body_inv_mass=body_inv_mass,
                    model_args=model_args, settings_args=settings_args, pairs_args=pairs_args,
                    solver_args=solver_args, solver_v=solver_v, solver_w=solver_w, impact_sweep=impact_sweep,
                    impact_since=impact_since)
        if self.device.is_cuda and not self.device.is_capturing:
            # stepped without a graph: reading the flag back would stall; on an empty set the
            # launches return at once
            self._stage(**args)
            return
        if recount:
            wp.launch(overflow_present, dim=1, device=self.device, inputs=[contacts.color_start, self.present])
        wp.capture_if(self.present, on_true=self._stage, **args)

    def _stage(self, mode, dim, recount, contacts, body_inv_mass, model_args, settings_args, pairs_args, solver_args,
               solver_v, solver_w, impact_sweep, impact_since):
        if recount:
            self.solver_overflow_split.zero_()
            self.solver_overflow_owner.fill_(NO_OWNER)
            wp.launch(overflow_count, dim=dim, device=self.device, **gpu_blocks(self.device), inputs=[
                contacts.color_start, contacts.color_pairs_sorted, body_inv_mass, contacts.pair_body,
                self.solver_overflow_split, self.solver_overflow_owner])
        if mode == MODE_IMPACT:
            # one split sweep per impact sweep, as the colours get (the stage repeats its sweeps)
            wp.launch(overflow_impact_pass, dim=dim, device=self.device, **gpu_blocks(self.device), inputs=[
                impact_sweep, impact_since, contacts.color_start, contacts.color_pairs_sorted, model_args,
                settings_args, pairs_args, solver_args, self.solver_overflow_split, self.solver_overflow_velocity,
                self.solver_overflow_shift, self.solver_overflow_hit])
            launch(overflow_impact_apply, dim, key=self, device=self.device, inputs=[
                impact_sweep, contacts.color_start, contacts.color_pairs_sorted, contacts.pair_body,
                self.solver_overflow_owner, self.solver_overflow_velocity, self.solver_overflow_shift,
                self.solver_overflow_hit, solver_v, solver_w, solver_args.solver_toi_shift,
                solver_args.solver_impact_stamp, solver_args.solver_event_partner])
            return
        for _ in range(1 if mode == MODE_WARM_START else OVERFLOW_ITERATIONS):
            wp.launch(overflow_pair_pass, dim=dim, device=self.device, **gpu_blocks(self.device), inputs=[
                mode, contacts.color_start, contacts.color_pairs_sorted, model_args, settings_args, pairs_args,
                solver_args, self.solver_overflow_split, self.solver_overflow_velocity])
            # no atomics: through warp_sim.launch, so race_check sees that no two threads write a body
            launch(overflow_apply, dim, key=self, device=self.device, inputs=[
                contacts.color_start, contacts.color_pairs_sorted, contacts.pair_body, self.solver_overflow_owner,
                self.solver_overflow_velocity, solver_v, solver_w])
