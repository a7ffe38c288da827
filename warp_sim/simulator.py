"""Simulator: owns the model, two states, contacts and the solver; runs whole steps.

One step of ``dt`` is ``substeps`` substeps of h = dt / substeps; ``substeps`` is the fewest, and
with ``auto_substeps`` (the default) the simulator runs more where the columns the scene starts
with would sag past ``column_sag`` under their soft contacts (column_sag.py; ``Simulator.substeps``
and ``substep_plan`` say what runs and why).  With ``contact_update = "substep"`` each substep is

    [pairs: broad -> narrow -> warm-start carry -> colouring] -> collide_terrain(state_0)
    -> solver.step(state_0 -> state_1) -> [pairs: keep impulses] -> swap
    (without pairs, the first of an odd number of substeps runs in place: solvers/solver.py)

With ``"step"`` (the default, Box2D v3's soft step) the collision stages run once, at the start
of the step, with speculative margins widened to cover the whole step (the pairs first, so a box's
terrain windows cover what a partner's blow could give it: collide/struck_reach.py); the substeps then
solve those contacts with gaps updated from the bodies' motion (solvers/staged.py).  That
applies to scenes with body-body contact; the fused terrain-only kernel re-collides every
substep either way.  Then, with sleeping on, the sleep timers are updated (sleep.py).  The
terrain kernel runs only when the scene has a terrain and the pair pipeline only when it has
body-body contact (``body_contact``), so a scene pays for what it uses.
``graph`` (default: on CUDA) captures the whole step, terrain, pairs, colours, substeps,
restitution and sleeping, as one graph and replays it (on the CPU with Warp's CPU capture, which
tests use to prove the CUDA contract).  Nothing inside a captured step is read back: launches
are sized by capacities and bounds and their idle threads return at once (collide/pair_pipeline.py).
The first step runs directly (it loads the modules and makes the scratch buffers that are
created on first use); settings changes and capacity growth capture again.  The CPU slab
schedule reads its slab counts back, so a graph on the CPU uses the colour schedule.

Capacity: no step runs with truncated contacts.  Direct CPU stepping reads the broad phase's
demand right after it runs and, on overflow, grows the buffers and collides again before
anything was written.  Captured steps (and CUDA) read nothing inside the step: the broad phase's
demand sets a device flag, ``step`` reads it once per call, and on overflow restores the state
saved at the call's start, grows the buffers and runs the steps again (re-capturing the graph).
Each growth is reported once, as a RuntimeWarning.  An explicit ``contact_max`` is a hard limit
instead: ContactOverflowError (a captured call restores its starting state first).
"""

from __future__ import annotations

import dataclasses
import functools
import time
import warnings
from dataclasses import dataclass

import numpy as np
import warp as wp

from .collide import collide_terrain
from .collide.struck_reach import StruckReach
from .collide.narrow_phase import reach_outrun
from .collide.pair_pipeline import MovedBodies, PairContactPipeline, default_pair_capacity
from .sleep import AwakeModel, Sleep
from .integrate import PRE_KICK_FRACTION
from .kernel_args import BodyModel, BodyState, TerrainContacts, TerrainModel, bind
from .launch import cpu_threads, gpu_blocks, hot, launch
from .model import Model
from .solvers.pair_refresh import refresh_turned
from .config import NonFiniteStateError, SimConfig  # noqa: F401 (SimConfig is imported from here too)
from .solvers.solver import SolverSettings, make_solver
from .terrain import TERRAIN_NONE, FourierTerrain, PlaneTerrain
from .types import SHAPE_BOX, SHAPE_SPHERE
from .column_sag import plan_substeps, scene_lean
from .validation import CONTACT_UPDATES, PAIR_SCHEDULES, SIM_SCHEMA, SOLVERS, STEP_COUNT, check_fields  # noqa: F401
from .validation import check as check_value

# No kernel here is differentiated: skip generating (and compiling) the adjoints.
wp.set_module_options({"enable_backward": False})


@wp.kernel
def advance_step_counter(sim_step: wp.array(dtype=wp.int32)):
    sim_step[0] = sim_step[0] + 1


@wp.kernel
def note_pair_overflow(pair_demand: wp.array(dtype=wp.int64), capacity: int, overflow: wp.array(dtype=wp.int64)):
    """overflow[0] = the largest demand of the steps since it was cleared, once it exceeded capacity."""
    if pair_demand[0] > wp.int64(capacity):
        overflow[0] = wp.max(overflow[0], pair_demand[0])


@wp.kernel
def count_outrun_pass(passes: wp.array(dtype=wp.int32)):
    passes[0] = passes[0] + 1


@dataclass
class ReferencePose:
    """The poses at which a step's contacts were found, with the velocities of now: what a
    mid-step pass collides (Simulator._recollide_outrun)."""

    body_pos: wp.array
    body_rot: wp.array
    body_vel: wp.array
    body_angmom: wp.array


def simulation_device(model: Model, config: SimConfig):
    """The Warp device of ``config.device``, which must be the one the model was finalized on: a
    mismatch would otherwise surface as a launch error deep inside the first step."""
    from .validation import ValidationError

    model_device = wp.get_device(model.device)
    try:
        device = wp.get_device(config.device)
    except (ValueError, RuntimeError):
        raise ValidationError(f"SimConfig device {config.device!r} is not available ({wp.get_cuda_device_count()} "
                              f"CUDA devices found); the model is on {model_device.alias!r}") from None
    if device != model_device:
        raise ValidationError(f"SimConfig device {config.device!r} is not the model's device {model_device.alias!r}: "
                              f"finalize the builder on {config.device!r}, or set device = {model_device.alias!r}")
    return device


class Simulator:
    # Skip box checkpoints that provably cannot reach the Fourier surface (collide/terrain_contact.py).
    # It changes no result; tests turn it off to check exactly that.
    terrain_cull = True
    # A warm sphere's closest point from the third-order jet of one terrain sample where that is as
    # near as the search's tolerance (collide/closest_jet.py); tests turn it off to compare.
    closest_jet = True
    # With contacts found once per step, find the spheres' terrain contacts every substep anyway
    # (collide_terrain, refresh_spheres); bench/rain.py measures both.
    refresh_sphere_contacts = True

    def __init__(self, model: Model, config: SimConfig):
        config.validate()  # fields may have been set after construction
        from .limits import check_simulator_memory, warn_heavy_gravity

        self.device = simulation_device(model, config)
        check_simulator_memory(model, config)  # before allocating contact buffers the machine lacks
        self.model = model
        self.config = config
        self.use_graph = self.device.is_cuda if config.graph is None else bool(config.graph)
        if self.use_graph and config.pair_schedule == "domains":
            raise ValueError("pair_schedule 'domains' reads its slab counts back and cannot be captured; "
                             "set graph = false or pair_schedule = 'colors', got graph = true")
        if self.use_graph and config.broad_phase == "grid_hash" and config.body_contact:
            raise ValueError("broad_phase 'grid_hash' sizes wp.HashGrid on the host and cannot be captured; "
                             "set graph = false or another broad phase, got graph = true")
        self.substep_plan = plan_substeps(model, config)
        self.substeps = self.substep_plan.substeps
        warn_heavy_gravity(model, config, self.substeps)
        self.solver = make_solver(self._solver_settings(), config.gravity, self.device, model.body_count)
        self.states = [model.state(), model.state()]
        dynamic = int(np.count_nonzero(model.host["body_inv_mass"] > 0))
        # with sleeping on, every kernel sees sleeping bodies as static (sleep.py)
        self.sleep = None
        self.physics_model = model
        if config.sleep and dynamic >= 1:
            self.sleep = Sleep(model, config.sleep_velocity, config.sleep_time, self.device,
                               float(np.linalg.norm(config.gravity)), self._closing_kick())
            self.physics_model = AwakeModel(model, self.sleep.body_inv_mass_awake)
        self.pairs = None
        self._color_sizes = None
        capacity = 0
        if config.body_contact and model.body_count >= 2 and dynamic >= 1:
            capacity = config.contact_max or default_pair_capacity(model.body_count)
            self._make_pairs(capacity)
        self.contacts = model.contacts(capacity)
        # max_penetration's scratch buffer: as large as the contacts, so made on first use only
        # (a run that never asks for the diagnostic does not pay for it on the device)
        self._probe = None
        self.pair_overflow = wp.zeros(1, dtype=wp.int64, device=self.device)
        self.outrun = wp.zeros(1, dtype=wp.int32, device=self.device)
        self.struck = StruckReach(model.body_count, self.device)  # collide/struck_reach.py
        self.outrun_passes = wp.zeros(1, dtype=wp.int32, device=self.device)  # mid-step passes run, ever
        self._saved = None  # the state at the start of a step() call, when its steps are captured
        self._warm = False
        self.body_bad_step = wp.full(model.body_count, -1, dtype=wp.int32, device=self.device)
        self.bad_count = wp.zeros(1, dtype=wp.int32, device=self.device)
        self.step_count = 0
        self._gravity_magnitude = float(np.linalg.norm(config.gravity))
        self.graph = None
        self.profile = False  # when set, step() records per-stage wall time in stage_times [s]
        self.stage_times: dict[str, float] = {}

    def _make_pairs(self, capacity: int):
        config = self.config
        # with the slab schedule only push-out still walks colours
        self.pairs = PairContactPipeline(self.physics_model, config.broad_phase, capacity, self.device,
                                         self._domain_count(config),
                                         colors=config.solver == "pushout")
        self.pairs.capturable = self.use_graph or self.device.is_cuda

    @property
    def state(self):
        return self.states[0]

    @property
    def time(self) -> float:
        return self.step_count * self.config.dt

    @property
    def substep_dt(self) -> float:
        return self.config.dt / self.substeps

    def _closing_kick(self) -> tuple:
        """(1 - alpha) g h: the gravity each substep adds after its solve (integrate.py)."""
        share = 1.0 - PRE_KICK_FRACTION[self.config.integrator]
        return tuple(float(share * self.substep_dt * g) for g in self.config.gravity)

    def collide(self, state, contacts, h: float, speculative_margin: float, refresh_spheres: bool = False,
                struck: bool = False, carry_still: bool = True):
        """Terrain contacts of ``state``; ``refresh_spheres``: only the spheres', found again between a
        step's passes, relative to the pass's pose; ``struck``: boxes' windows opened with the reach their
        partners could give them (collide/struck_reach.py); ``carry_still``: still slots carried (still_contacts.py)."""
        m = self.physics_model
        if m.terrain_kind == TERRAIN_NONE or m.checkpoint_count == 0:
            return
        launch(collide_terrain, dim=m.body_count, key=contacts, inputs=[
            # Model
            bind(BodyModel, m, m), bind(TerrainModel, m, m),
            # Settings
            h, float(np.linalg.norm(self.config.gravity)), speculative_margin, int(self.terrain_cull),
            int(refresh_spheres), int(struck), int(self.config.face_search), int(self.config.prune_face_points),
            int(self.closest_jet), int(carry_still and self.config.still_contacts),
            # State in, Solver in, In
            bind(BodyState, state, state), self.solver.solver_ref_pos, self.struck.body_struck_reach,
            # Contacts
            bind(TerrainContacts, contacts, contacts),
        ], device=self.device)

    def _stage(self, name: str, fn, *args):
        """Run one stage; with ``profile`` set, synchronise and add its wall time to stage_times."""
        if not self.profile:
            return fn(*args)
        wp.synchronize_device(self.device)
        start, out = time.perf_counter(), fn(*args)
        wp.synchronize_device(self.device)
        self.stage_times[name] = self.stage_times.get(name, 0.0) + time.perf_counter() - start
        return out

    def _domain_count(self, config) -> int:
        """Slabs for the CPU pair schedule (solvers/domains.py): one per CPU thread; 0 = colours."""
        schedule = config.pair_schedule
        if schedule == "domains" and not self.device.is_cpu:
            raise ValueError(f"pair_schedule 'domains' runs on the CPU only, got device {config.device!r}")
        if config.solver != "soft_step" or schedule == "colors" or not self.device.is_cpu or self.use_graph:
            return 0
        return cpu_threads()

    def _collides_once_per_step(self) -> bool:
        return self.pairs is not None and self.config.contact_update == "step" and self.config.solver == "soft_step"

    def _simulate_one_step(self):
        if self._collides_once_per_step():
            self._simulate_one_step_collide_once()
        else:
            self._simulate_one_step_collide_each_substep()
        if self.sleep is not None:
            self._stage("sleep", self.sleep.update, self.states[0], self.config.dt, self.contacts)
        wp.launch(advance_step_counter, dim=1, inputs=[self.solver.sim_step], device=self.device)

    def _simulate_one_step_collide_once(self):
        dt = self.config.dt
        h = self.substep_dt
        margin = self.config.speculative_margin
        # the speculative windows cover the whole step: terrain slots open while the gap is
        # closable within dt, pairs are found with bounds swept over dt
        color_sizes = self._collide_pass(dt, margin, dt)
        refresh = self._refreshes_spheres()
        for k in range(self.substeps):
            if k > 0 and self.config.recollide_outrun:
                self._stage("pairs", self._recollide_outrun, dt - k * h, margin)
                color_sizes = self._color_sizes
            if k > 0 and refresh:
                self._stage("terrain", self.collide, self.states[0], self.contacts, h, margin, True)
            if k > 0 and self.config.turn_refresh > 0.0:
                self._stage("pairs", refresh_turned, self.physics_model, self.states[0], self.solver, self.pairs,
                            self.contacts, margin, self.config.turn_refresh)
            after_impacts = None
            if self.config.recollide_outrun and self.solver.runs_impacts(self.physics_model):
                after_impacts = functools.partial(self._recollide_outrun, dt - k * h, margin, True)
            self._stage("solve", self.solver.step, self.physics_model, self.states[0], self.states[1], self.contacts,
                        h, self.body_bad_step, self.bad_count, color_sizes, k == 0, self.pairs.domain_schedule(),
                        k > 0 and refresh, after_impacts)
            color_sizes = self._color_sizes
            self.states[0], self.states[1] = self.states[1], self.states[0]
        self._stage("solve", self.pairs.store, self.contacts)
        self._keep_output_buffer()

    def _recollide_outrun(self, remaining: float, margin: float, after_impacts: bool = False, impacts_again=None):
        """Find the pairs again, only if some body has sped up beyond the reach the step's pass
        gave it (a ball at rest struck by one at 40 m/s crosses 0.67 m in the step that hit it;
        its pair with a wall 13 cm away was never found, and it went through).  Checked before
        each later substep, and, in a scene with restitution, between each substep's impact stage
        and its solve (``after_impacts``: the struck body would otherwise cross h v unchecked
        in that substep).  ``remaining``: the time left in the step.  The new pass runs at the
        step's reference pose, so the manifolds found then and now share one pose and the
        substeps' anchors stay valid; the impulses so far are kept as its warm start.  The flag
        is read on the device (wp.capture_if): a captured step records the pass as a conditional
        node.  Terrain contacts are not found again (spheres' are, every substep; a box a partner
        could strike opened its slots for that blow at the pass: collide/struck_reach.py).
        ``impacts_again``: the solver's impact sweeps, rerun after a pass made between the impact
        stage and the solve, so that the contacts it found bounce in this substep."""
        m = self.physics_model
        solver = self.solver
        state = self.states[0]
        self.outrun.zero_()
        # atomics: one plain launch, never split
        wp.launch(reach_outrun, dim=m.body_count, device=self.device, **gpu_blocks(self.device), inputs=[
            m.body_bound_radius, m.body_inv_mass, m.body_inv_inertia, remaining, self._gravity_magnitude, margin,
            int(after_impacts), solver.solver_ref_pos, state.body_pos, state.body_rot, state.body_vel,
            state.body_angmom, solver.solver_v, solver.solver_w, self.pairs.body_reach, self.outrun])

        def recollide():
            reference = ReferencePose(solver.solver_ref_pos, solver.solver_ref_rot, state.body_vel,
                                      state.body_angmom)
            moved = MovedBodies(state.body_pos, state.body_rot, state.body_vel, state.body_angmom, solver.solver_v,
                                solver.solver_w, int(after_impacts))
            self.pairs.store(self.contacts)
            self._collide_pairs(margin, remaining, reference, moved)
            wp.launch(count_outrun_pass, dim=1, device=self.device, inputs=[self.outrun_passes])
            if impacts_again is not None:
                impacts_again(self._color_sizes)

        wp.capture_if(self.outrun, on_true=recollide)
        return self._color_sizes

    def _refreshes_spheres(self) -> bool:
        """Spheres' terrain contacts are found every substep (collide_terrain): a closest-point
        search warm-started from the last one, a few terrain evaluations per sphere and substep."""
        m = self.model
        return (self.refresh_sphere_contacts and m.terrain_kind != TERRAIN_NONE and m.checkpoint_count > 0
                and bool(np.any(m.host["body_shape"] == SHAPE_SPHERE)))

    def _collide_pass(self, h: float, margin: float, sweep_time: float):
        """Pair and terrain collision of states[0]; with sleeping on, the sleepers an awake body touches
        are woken and, only then, the pass is run again with them awake (sleep.py).  Returns the colour sizes."""
        def collide():
            m, state, pairs = self.physics_model, self.states[0], self.pairs  # pairs first: struck_reach.py
            if pairs is not None:
                self._stage("pairs", functools.partial(self._collide_pairs, partition=False), margin, sweep_time)
                self._stage("terrain", self.struck.find, bind(BodyModel, m, m), state, self.contacts, margin, h)
            terrain = functools.partial(self.collide, struck=pairs is not None)  # the boxes' struck reach
            self._stage("terrain", terrain, state, self.contacts, h, margin)
            if pairs is not None:
                self._stage("pairs", pairs.partition, state, self.contacts)

        collide()
        if self.sleep is not None and self.pairs is not None:
            self._stage("sleep", self.sleep.wake_touched, self.contacts, collide)
        return self._color_sizes if self.pairs is not None else None

    def _keep_output_buffer(self, in_place: bool = False):
        if self.substeps % 2 == 1 and not in_place:
            # Keep the captured graph's output in the buffer it started from.
            self.states[1].assign(self.states[0])
            self.states[0], self.states[1] = self.states[1], self.states[0]

    def _simulate_one_step_collide_each_substep(self):
        h = self.substep_dt
        in_place = self.pairs is None and self.substeps % 2 == 1 and self.solver.fused_in_place  # solver.py
        for k in range(self.substeps):
            color_sizes = self._collide_pass(h, self.config.speculative_margin, h)
            domains = self.pairs.domain_schedule() if self.pairs is not None else None
            out = self.states[0] if in_place and k == 0 else self.states[1]
            self._stage("solve", self.solver.step, self.physics_model, self.states[0], out, self.contacts,
                        h, self.body_bad_step, self.bad_count, color_sizes, True, domains)
            if self.pairs is not None:
                self._stage("solve", self.pairs.store, self.contacts)
            if out is self.states[1]:
                self.states[0], self.states[1] = self.states[1], self.states[0]
        self._keep_output_buffer(in_place)

    def _collide_pairs(self, margin: float, sweep_time: float, state=None, moved=None, partition: bool = True):
        """The pair pipeline on states[0] (or on ``state``, with ``moved``: a mid-step pass, see
        PairContactPipeline.collide); grows the buffers first if they would overflow (direct stepping checks
        on the host right after the broad phase; a captured step raises the device flag that ``step`` reads)."""
        state = self.states[0] if state is None else state
        self.pairs.measure_patch = self.config.face_friction == "patch"  # collide/contact_patch.py

        def grow(demand: int):
            if self.config.contact_max:
                self.contacts.pair_demand.assign(np.array([demand], dtype=np.int64))
                self.contacts.check_overflow()
            self._grow(demand)
            return self.pairs.collide(state, self.contacts, margin, sweep_time, self._gravity_magnitude,
                                      on_overflow=grow, moved=moved, partition=partition)

        sizes = self.pairs.collide(state, self.contacts, margin, sweep_time, self._gravity_magnitude,
                                   on_overflow=grow, moved=moved, partition=partition)
        if self.pairs.capturable:
            wp.launch(note_pair_overflow, dim=1, device=self.device,
                      inputs=[self.contacts.pair_demand, self.pairs.capacity, self.pair_overflow])
        self._color_sizes = sizes
        return sizes

    def step(self, count: int = 1, check: bool = True):
        """Advance ``count`` steps of dt; raises NonFiniteStateError naming the first bad body.

        Captured steps raise a device flag on pair overflow, read once per call: the ``count``
        steps are then run again from the state saved at the start, with grown buffers (module
        docstring).  Direct stepping grows the buffers within the step instead."""
        count = check_value(STEP_COUNT, count, "count", "Simulator.step")
        if self.pairs is None or not self.pairs.capturable:
            self._run_steps(count)
        else:
            self._save()
            self.pair_overflow.zero_()
            start = self.step_count
            self._run_steps(count)
            demand = int(self.pair_overflow.numpy()[0])
            while demand > 0:
                self._restore_saved(start)
                if self.config.contact_max:
                    self.contacts.pair_demand.assign(np.array([demand], dtype=np.int64))
                    self.contacts.check_overflow()
                self._grow(demand)
                self._restore_saved(start)
                self.pair_overflow.zero_()
                self._run_steps(count)
                demand = int(self.pair_overflow.numpy()[0])
        if self.pairs is not None:
            self.pairs.report_color_overflow()  # read once per call, like the pair overflow above
        if check:
            self.check_finite()

    def _run_steps(self, count: int):
        with hot():  # launch.py: split launches hand off to spinning workers while the steps run
            for _ in range(count):
                if self.use_graph and not self.profile and self._warm:
                    if self.graph is None:
                        with wp.ScopedCapture(device=self.device) as capture:
                            self._simulate_one_step()
                        self.graph = capture.graph
                    wp.capture_launch(self.graph)
                else:
                    self._simulate_one_step()
                    self._warm = True
                self.step_count += 1

    def _save(self):
        arrays = self._persistent_arrays()
        if self._saved is None or len(self._saved) != len(arrays) or any(
                a.shape != b.shape for a, b in zip(arrays, self._saved)):
            self._saved = [wp.empty_like(a) for a in arrays]
        for dst, src in zip(self._saved, arrays):
            wp.copy(dst, src)

    def _restore_saved(self, step_count: int):
        for dst, src in zip(self._persistent_arrays(), self._saved):
            wp.copy(dst, src, count=min(dst.size, src.size))
        self.step_count = step_count

    def _grow(self, demand: int):
        """Rebuild the pair pipeline with room for 1.5x the demand; the contact buffer keeps its
        terrain slots and last pass's pairs (the warm-start source)."""
        old = self.pairs.capacity
        capacity = max(2 * old, int(1.5 * demand) + 64)
        warnings.warn(f"body-body candidate pairs ({demand}) exceeded the pair buffer ({old}); grown to "
                      f"{capacity} pairs and the step redone", RuntimeWarning, stacklevel=4)
        self._make_pairs(capacity)
        self.contacts.grow_pairs(capacity)
        self._probe = None
        self.invalidate_graph()

    def invalidate_graph(self):
        """Call after changing model or settings: the captured graph (and still bodies' slots) hold the old."""
        self.graph = None
        self.contacts.forget_anchors()

    def check_finite(self):
        if int(self.bad_count.numpy()[0]) == 0:
            return
        steps = self.body_bad_step.numpy()
        bad = np.flatnonzero(steps >= 0)  # named: of the earliest step's bodies, the lowest scene index
        earliest = sorted(self.model.body_scene_index[bad[steps[bad] == steps[bad].min()]].tolist())
        first = int(self.model.body_internal_index[earliest[0]])
        step = int(steps[first]) + 1
        shape = "box" if self.model.host["body_shape"][first] == SHAPE_BOX else "sphere"
        raise NonFiniteStateError(earliest[0], step, step * self.config.dt, shape, tuple(earliest[1:]))

    def reset(self):
        self.states = [self.model.state(), self.model.state()]
        self.contacts = self.model.contacts(self.pairs.capacity if self.pairs else 0)
        self.body_bad_step.fill_(-1)
        self.bad_count.zero_()
        self.solver.sim_step.zero_()
        self.solver.solver_support.zero_()
        if self.sleep is not None:
            self.sleep.wake_all()
        self.step_count = 0
        self.graph = None

    # Editing and time travel ------------------------------------------------------------------

    def snapshot(self) -> dict:
        """Everything the next step reads: body state, contact warm-start data and counters.

        Restoring it and stepping reproduces the original run bit for bit on CPU.
        """
        return {"step_count": self.step_count, "arrays": [wp.clone(a) for a in self._persistent_arrays()]}

    def _persistent_arrays(self) -> list:
        c = self.contacts
        arrays = [*self.state.fields(), c.terrain_contact_active, c.terrain_contact_point, c.terrain_contact_normal,
                  c.terrain_contact_depth, c.terrain_contact_normal_impulse, c.terrain_contact_tangent_impulse,
                  c.terrain_contact_surface, c.terrain_contact_anchor_pos, c.terrain_contact_anchor_quat,
                  self.solver.sim_step, self.solver.solver_support]
        if self.sleep is not None:
            arrays += [self.sleep.body_sleep_timer, self.sleep.body_sleep_speed, self.sleep.body_sleep_rise,
                       self.sleep.body_inv_mass_awake]
        if self.pairs is not None:
            arrays += [c.prev_pair_count, c.prev_pair_body, c.prev_pair_point_count, c.prev_pair_feature,
                       c.prev_pair_normal, c.prev_pair_point, c.prev_pair_normal_impulse, c.prev_pair_tangent_impulse]
        return arrays

    def restore(self, snap: dict):
        """Put back what ``snapshot()`` took, from this simulator or one built the same way;
        ValueError naming what does not fit (recording.check_snapshot)."""
        from .recording import check_snapshot

        targets = self._persistent_arrays()
        check_snapshot(snap, targets)
        for dst, src in zip(targets, snap["arrays"]):
            wp.copy(dst, src)
        self.step_count = int(snap["step_count"])

    def _solver_settings(self) -> SolverSettings:
        """The config's solver settings, with the depth past which a contact is pushed back within
        the substep (contact_rows.closed_contact_bias): the column sag the substep plan runs with,
        never under the column_sag setting.  With auto_substeps off a column may be planned to sag
        past the budget, and pushing its loaded contacts back would fight the load (a 1 kg cube
        under 1000 kg at 4 substeps, planned at 138 mm, was thrown out).  The setting, not the
        plan's budget scaled down for thin bodies (column_sag.plan_budgets): a pile of pebbles that
        forms later, which the plan does not foresee, sags by a length whatever their size, and
        pushed back from a fraction of a millimetre its loaded contacts would fight the load too."""
        return dataclasses.replace(self.config.solver_settings(),
                                   soft_depth=max(self.config.column_sag, self.substep_plan.sag))

    def set_terrain(self, terrain):
        """Replace the terrain the bodies collide with (GUI edits); takes effect next step."""
        self.model.set_terrain(terrain)
        self.wake_all()
        self.invalidate_graph()

    def wake_all(self):
        if self.sleep is not None:
            self.sleep.wake_all()

    def refreshed_pair_count(self) -> int:
        """Pairs found again mid-step (solvers/pair_refresh.py) since the last pass that found the
        pairs: in a step without a mid-step pass, that step's refreshes, counted over its later
        substeps (a pair refreshed before two substeps counts twice).  A measurement taken between
        steps (it reads the counts back to the host); the step itself never calls it."""
        if self.pairs is None:
            return 0
        live = min(int(self.contacts.pair_count.numpy()[0]), self.contacts.pair_max)
        return int(self.contacts.pair_refresh_count.numpy()[:live].sum())

    def awake_count(self) -> int:
        """Dynamic bodies not asleep."""
        if self.sleep is None:
            return int(np.count_nonzero(self.model.host["body_inv_mass"] > 0))
        return self.sleep.awake_count()

    def update_settings(self, **changes):
        """Change SimConfig fields (dt, substeps, gravity, integrator, ...) between steps.  Unknown
        names raise ValueError naming the field, and so do the settings the Simulator is built
        around (BUILD_SETTINGS: the device, the pair buffers and pipeline, sleeping, graph capture),
        which a change here would store and never apply."""
        for key in changes:
            if key not in SIM_SCHEMA:
                raise ValueError(f"unknown simulation setting {key!r}")
            if key in BUILD_SETTINGS and changes[key] != getattr(self.config, key):
                raise ValueError(f"SimConfig.{key} is fixed when the Simulator is built; build a new Simulator "
                                 f"to change it (got {changes[key]!r}, built with {getattr(self.config, key)!r})")
        for key, value in changes.items():
            check_value(SIM_SCHEMA[key], value, key, "SimConfig")
        for key, value in changes.items():
            setattr(self.config, key, value)
        self.config.validate()
        # between steps (the graph is captured again below): plan on the columns standing now, and
        # on the leaning columns the scene was set down with (column_lean.py)
        self.substep_plan = plan_substeps(self.model, self.config, self.state, lean=scene_lean(self.model, self.config))
        self.substeps = self.substep_plan.substeps
        self._gravity_magnitude = float(np.linalg.norm(self.config.gravity))
        if self.sleep is not None:
            self.sleep.gravity_magnitude = self._gravity_magnitude
            self.sleep.sleep_velocity = self.config.sleep_velocity
            self.sleep.sleep_time = self.config.sleep_time
            self.sleep.closing_kick = self._closing_kick()
        support = self.solver.solver_support  # the next impacts read what the contacts held (staged.support_share)
        self.solver = make_solver(self._solver_settings(), self.config.gravity, self.device, self.model.body_count)
        self.solver.sim_step.assign(np.array([self.step_count], dtype=np.int32))
        wp.copy(self.solver.solver_support, support)
        self.wake_all()
        self.invalidate_graph()

    # Measurements -----------------------------------------------------------------------------

    def angular_velocity(self, state=None) -> np.ndarray:
        s = state or self.state
        rot = s.body_rot.numpy().astype(np.float64)
        angmom = s.body_angmom.numpy().astype(np.float64)
        inv_inertia = self.model.host["body_inv_inertia"].astype(np.float64)
        body = np.einsum("nji,nj->ni", rot, angmom) * inv_inertia
        return np.einsum("nij,nj->ni", rot, body)

    def kinetic_energy(self, per_body: bool = False):
        s = self.state
        mass = self.model.body_mass
        v = s.body_vel.numpy().astype(np.float64)
        omega = self.angular_velocity(s)
        angmom = s.body_angmom.numpy().astype(np.float64)
        ke = 0.5 * mass * np.einsum("ni,ni->n", v, v) + 0.5 * np.einsum("ni,ni->n", omega, angmom)
        return ke if per_body else float(ke.sum())

    def max_penetration(self) -> float:
        """Deepest penetration of the current state into the terrain or another body [m] (0 if none)."""
        probe = self.probe_contacts()
        # start the probe's closest-point searches where the live contacts left off
        wp.copy(probe.terrain_contact_active, self.contacts.terrain_contact_active)
        wp.copy(probe.terrain_contact_surface, self.contacts.terrain_contact_surface)
        self.collide(self.state, probe, self.substep_dt, 0.0, carry_still=False)
        depths = probe.active_terrain_depths()
        deepest = float(max(depths.max(), 0.0)) if depths.size else 0.0
        if self.pairs is not None:
            deepest = max(deepest, self.pairs.probe_depth(self.state, probe))
        return deepest

    def probe_contacts(self):
        """A scratch Contacts buffer the size of the live one, for diagnostics that find contacts
        without touching the solver's (max_penetration); made on first use."""
        if self._probe is None or self._probe.pair_max != self.contacts.pair_max:
            self._probe = self.model.contacts(self.contacts.pair_max)
        return self._probe

    def contact_count(self) -> int:
        """Active contacts of the last substep (terrain slots in use plus body-body pairs)."""
        return self.contacts.count()

    def terrain_record(self) -> dict:
        t = self.model.terrain
        if isinstance(t, FourierTerrain):
            return {
                "terrain_kind": "fourier", "terrain_amplitudes": t.amplitude_table(), "terrain_phases": t.phase_table(),
                "terrain_frequency": t.frequency, "terrain_scale": np.asarray(t.scale),
                "terrain_offset": np.asarray(t.offset),
            }
        if isinstance(t, PlaneTerrain):
            return {"terrain_kind": "plane", "terrain_normal": np.asarray(t.normal), "terrain_plane_offset": t.offset}
        return {"terrain_kind": "none"}


# what Simulator.__init__ builds from (arrays, pipelines, the device): update_settings refuses them
BUILD_SETTINGS = ("device", "body_contact", "contact_max", "sleep", "broad_phase", "pair_schedule", "graph")
