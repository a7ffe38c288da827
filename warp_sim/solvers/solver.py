"""Solvers: ``step(model, state_in, state_out, contacts, dt)`` advances one substep.

A scene without body-body contact runs the fused per-body kernel (soft_step.py): one launch
per substep.  With body-body contact the same algorithm runs as the staged launches of
staged.py and pair_solve.py, colour by colour or slab by slab.  ``PushoutSolver`` is the
thesis's response, its own solver; ``make_solver`` picks the one the settings name.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass
from types import SimpleNamespace

import warp as wp

from ..kernel_args import BadSteps, BodyModel, BodyState, PairContacts, TerrainContacts, bind
from ..launch import LIGHT_CHUNK, PAIR_CHUNK, gpu_blocks, launch
from ..types import INTEGRATORS, ROTATIONS
from ..schedule.coloring import COLOR_COUNT
from .domains import DOMAIN_SWEEP
from .pushout import pushout_pair, pushout_terrain_impulse, pushout_terrain_position
from .impact import IMPACT_INNER, count_travel_loop, impact_begin, impacts_travelling, pair_contact_times, terrain_impact
from .impact_joint import joint_phase_in_order, pair_joint_pass, terrain_joint_impact, terrain_members
from .pair_overflow import OverflowPairs
from .pair_solve import (MODE_IMPACT, MODE_IMPACT_BOUNCE, MODE_IMPACT_JOINT, MODE_SOLVE, MODE_WARM_START, RELAX_MODES,
                         chain_pass, PAIR_PASS)
from .plan import (AFTER_IMPACTS, FINALIZE, FIRST_SEQUENTIAL_ROUND, IMPACT, IMPACT_BEGIN, IMPACT_TRAVEL, INTEGRATE,
                   PREPARE, RELAX, SOLVE, TRAVEL_LOOPS, WARM_START, impact_first_since, impact_round_sweeps, substep_plan,
                   travel_rounds)
from .soft_step import (CONVERGENCE_GRAVITY_SHARE, RELAX_PASSES, push_cap, soft_coefficients, soft_load, solve_and_integrate,
                        sweep_tolerance)
from .solver_args import DomainSlabs, JointImpacts, SolverBodies, StepSettings
from .staged import (MAKE_ROWS, MAKE_ROWS_ALWAYS, MAKE_ROWS_NONE, finalize_bodies, integrate_positions, prepare_bodies,
                     terrain_sweep)

JOINT_MODES = (MODE_IMPACT_JOINT, MODE_IMPACT_BOUNCE)


@dataclass
class SolverSettings:
    """Contact solver constants (SimConfig documents each).  Sweeps per substep: 2 with bias plus 1
    relax.  Box2D v3 does 1 + 1; in 3-D that let a pyramid of base 10 creep 2.5 cm in 4 s, while
    2 + 1 holds it to 0.5 mm and a 20-box stack to 5 mm, at 3/4 of the cost of the 4 + 2 of
    Solver2D's tests (tests/test_body_contact.py).  Contact stiffness: Box2D's cap of a quarter of
    the substep rate, 60 Hz at 4 substeps of 1/60 s, and stiffer with more substeps
    (warp_sim/column_sag.py); ``contact_hertz`` caps it lower (30 Hz, Box2D's 2-D default, lets a
    3-D stack of 20 fall)."""

    integrator: str = "semi_implicit"
    rotation: str = "quaternion"
    iterations: int = 2
    relax_iterations: int = 1
    relax_passes: int = RELAX_PASSES
    contact_hertz: float | None = None  # None: a quarter of the substep rate (column_sag.contact_hertz)
    damping_ratio: float = 10.0
    max_push_velocity: float = 3.0
    soft_depth: float = 0.0075  # [m] SimConfig.column_sag: deeper, a contact's excess is pushed out in a substep
    restitution_threshold: float = 0.0
    convergence_tolerance: float = 1.0e-5
    convergence_gravity_share: float = CONVERGENCE_GRAVITY_SHARE
    solver: str = "soft_step"
    overflow_pairs: str = "auto"  # "auto": "split" on CUDA, "in_order" on the CPU (pair_overflow.py)
    face_friction: str = "patch"  # "points": friction at the manifold's points (collide/contact_patch.py)
    simultaneous_impacts: str = "joint"  # "sequential": in pair order, no joint phase (impact_joint.py)
    impacts: str = "auto"  # "auto": the impact stage only in scenes with restitution; "always"


class _LaunchSite:
    """Owner of one call site's recorded launches (launch.py) for one state buffer."""


class SoftStepSolver:
    # Each body's list of active terrain slots is built once per collision pass (staged.prepare_body);
    # tests turn this off to check that rebuilding it every substep changes nothing.
    reuse_terrain_rows = True
    # Without pairs a substep is the fused launch, in which body i reads and writes body i's state
    # alone (soft_step.solve_and_integrate): it may run in place, and the Simulator runs the first
    # of an odd number of substeps so, instead of copying the step's result back into the buffer
    # it started from (5 arrays, 88 bytes a body-step)
    fused_in_place = True

    def __init__(self, settings: SolverSettings, gravity, device, body_count: int = 0):
        self.settings = settings
        self.gravity = wp.vec3(*gravity)
        self.device = device
        self.sim_step = wp.zeros(1, dtype=wp.int32, device=device)
        self._sites = weakref.WeakKeyDictionary()
        n = max(body_count, 1)
        self.solver_v = wp.zeros(n, dtype=wp.vec3, device=device)
        self.solver_w = wp.zeros(n, dtype=wp.vec3, device=device)
        self.solver_w0 = wp.zeros(n, dtype=wp.vec3, device=device)
        self.solver_inv_inertia = wp.zeros(n, dtype=wp.mat33, device=device)
        self.solver_rolling = wp.zeros(n, dtype=wp.vec3, device=device)
        self.solver_load_mass = wp.zeros(n, dtype=float, device=device)
        self.solver_shift_v = wp.zeros(n, dtype=wp.vec3, device=device)
        self.solver_shift_w = wp.zeros(n, dtype=wp.vec3, device=device)
        # pose at which the contacts were found, and the motion since (staged.py)
        self.solver_ref_pos = wp.zeros(n, dtype=wp.vec3, device=device)
        self.solver_ref_rot = wp.zeros(n, dtype=wp.mat33, device=device)
        self.solver_drift_p = wp.zeros(n, dtype=wp.vec3, device=device)
        self.solver_drift_r = wp.zeros(n, dtype=wp.mat33, device=device)
        # an impact's time-of-impact position shift, spent by the next integration (impact.py)
        self.solver_toi_shift = wp.zeros(n, dtype=wp.vec3, device=device)
        # the impact sweep that last changed a body's velocity (impact.unchanged_since)
        self.solver_impact_stamp = wp.zeros(n, dtype=wp.int32, device=device)
        # whether a blow is still travelling after the impact rounds, and the loop's passes (plan.IMPACT_TRAVEL)
        self.travelling = wp.zeros(1, dtype=wp.int32, device=device)
        self.travel_loops = wp.zeros(1, dtype=wp.int32, device=device)
        # when the earliest of a body's pairs closes within the substep (impact.pair_contact_times)
        self.solver_pair_toi = wp.zeros(n, dtype=float, device=device)
        # when and with whom each body's last impact of the substep struck (impact.pair_event_start)
        self.solver_event_time = wp.zeros(n, dtype=float, device=device)
        self.solver_event_partner = wp.full(n, -1, dtype=wp.int32, device=device)
        # the share of gravity each body's contacts held in the last substep (staged.support_share)
        self.solver_support = wp.zeros(n, dtype=float, device=device)
        # each body's terrain patch: centre (as an arm) and friction arm scale (collide/contact_patch.py)
        self.solver_twist = wp.zeros(n, dtype=wp.vec4, device=device)
        # the joint phase's scratch (impact_joint.py)
        self.impact_v_start = wp.zeros(n, dtype=wp.vec3, device=device)
        self.impact_w_start = wp.zeros(n, dtype=wp.vec3, device=device)
        self.impact_terrain_event = wp.zeros(n, dtype=wp.vec2, device=device)
        self.impact_member_count = wp.zeros(n, dtype=wp.int32, device=device)

    def _soft(self, dt: float):
        # one vec4 object per dt, so recorded launches see an unchanged argument
        if getattr(self, "_soft_dt", None) != dt:
            self._soft_dt = dt
            self._soft_value = soft_coefficients(dt, self.settings.contact_hertz, self.settings.damping_ratio,
                                                 self.settings.soft_depth)
        return self._soft_value

    def step(self, model, state_in, state_out, contacts, dt: float, body_bad_step, bad_count, color_sizes=None,
             fresh_contacts: bool = True, domains=None, rebuild_rows: bool = False, after_impacts=None):
        """One substep.  ``color_sizes`` (pairs per colour, host ints) selects the staged path.

        ``fresh_contacts``: the contacts were found at ``state_in`` (else at an earlier substep's
        state, whose pose the staged solver keeps as the anchors' reference).
        ``domains``: a pair_pipeline.DomainSchedule; the staged soft step then sweeps slab by slab
        (solvers/domains.py) instead of colour by colour.
        ``rebuild_rows``: some terrain contacts were found again since the last substep (the
        simulator's sphere refresh), so every body's rows are rebuilt.
        ``after_impacts(impacts_again)``: called between the impact stage and the solve (a scene
        with restitution), with the post-impact velocities in solver_v / solver_w; it may find
        the pairs again (Simulator._recollide_outrun), then calls ``impacts_again(colour sizes)``
        so that the contacts just found get their impacts in this substep too (a speculative
        contact left to the solve would stop the body at the wall and lose its bounce); it
        returns the colour sizes to solve with.
        """
        self._rebuild_rows = rebuild_rows
        a = self._args(model, state_in, state_out, contacts, dt, body_bad_step, bad_count,
                       color_sizes is not None)
        if color_sizes is None:
            self._step_fused(model, a)
        else:
            self._step_staged(model, contacts, a, color_sizes, fresh_contacts, domains, after_impacts)

    def _args(self, model, state_in, state_out, contacts, dt, body_bad_step, bad_count, staged: bool = True):
        """The struct arguments of a substep's launches (kernel_args.py), the same instances from one
        substep to the next unless an array was replaced; each State buffer keeps its own."""
        a = SimpleNamespace(
            model=bind(BodyModel, model, model), settings=self._step_settings(dt),
            state_in=bind(BodyState, state_in, state_in), state_out=bind(BodyState, state_out, state_out),
            slots=bind(TerrainContacts, contacts, contacts),
            bad_steps=bind(BadSteps, self, self, body_bad_step=body_bad_step, bad_count=bad_count),
            contacts=contacts, buffer_in=state_in)
        if staged:
            self._terrain_rows(model, contacts)
            self._impact_scratch(contacts)
            a.pairs = bind(PairContacts, contacts, contacts)
            a.solver = bind(SolverBodies, self, self)
            a.joint = bind(JointImpacts, self, self)
        return a

    def _step_settings(self, dt: float) -> StepSettings:
        s = self.settings
        key = (dt, tuple(self.gravity), s.integrator, s.rotation, s.contact_hertz, s.damping_ratio, s.soft_depth,
               s.max_push_velocity, s.restitution_threshold, s.convergence_tolerance, s.convergence_gravity_share,
               s.iterations, s.relax_iterations, s.relax_passes, s.impacts, s.face_friction)
        if getattr(self, "_settings_key", None) != key:
            # a new instance, never a changed one: recorded launches hold a packed copy (kernel_args.py)
            v = StepSettings()
            v.gravity, v.h, v.soft = self.gravity, dt, self._soft(dt)
            v.soft_load = soft_load(dt, self.gravity, s.contact_hertz, s.damping_ratio)
            v.integrator, v.rotation = INTEGRATORS[s.integrator], ROTATIONS[s.rotation]
            v.max_push_velocity = push_cap(s.max_push_velocity, self.gravity, dt, v.soft)
            v.restitution_threshold = s.restitution_threshold
            v.convergence_tolerance = sweep_tolerance(s.convergence_tolerance, s.convergence_gravity_share,
                                                      self.gravity, dt)
            v.iterations, v.relax_iterations = s.iterations, s.relax_iterations
            v.relax_passes = s.relax_passes
            v.impacts_always = int(s.impacts == "always")
            v.face_patch = int(s.face_friction == "patch")
            self._settings_key, self._settings_value = key, v
        return self._settings_value

    def _terrain_rows(self, model, contacts):
        """Each body's active slots, packed at the front of its slot range (contact_rows.py), and
        their count."""
        rows = getattr(self, "terrain_row_slot", None)
        if rows is None or rows.shape[0] < contacts.terrain_contact_active.shape[0]:
            self.terrain_row_slot = wp.zeros(contacts.terrain_contact_active.shape[0], dtype=wp.int32,
                                             device=self.device)
        counts = getattr(self, "terrain_row_count", None)
        if counts is None or counts.shape[0] < model.body_count:
            self.terrain_row_count = wp.zeros(max(model.body_count, 1), dtype=wp.int32, device=self.device)
        return self.terrain_row_slot, self.terrain_row_count

    def _impact_scratch(self, contacts):
        """Per terrain slot: the impact's normal and tangential impulses (impact.py); per pair, a
        simultaneous impact's member (impact_joint.py)."""
        slots = max(contacts.terrain_contact_active.shape[0], 1)
        normal = getattr(self, "impact_normal", None)
        if normal is None or normal.shape[0] < slots:
            self.impact_normal = wp.zeros(slots, dtype=float, device=self.device)
            self.impact_tangent = wp.zeros(slots, dtype=wp.vec3, device=self.device)
        pairs = max(getattr(contacts, "pair_max", 0), 1)
        events = getattr(self, "impact_pair_event", None)
        if events is None or events.shape[0] < pairs:
            self.impact_pair_event = wp.zeros(pairs, dtype=wp.vec2, device=self.device)
            self.impact_pair_acc = wp.zeros(pairs, dtype=wp.vec4, device=self.device)
            self.impact_member_list = wp.zeros(pairs + self.impact_v_start.shape[0], dtype=wp.int32,
                                               device=self.device)
        return self.impact_normal, self.impact_tangent

    def _site(self, state, *name):
        """The recorded-launch owner for this call site and this input state.  The two state buffers
        alternate, so a site keyed by both keeps its arguments unchanged from one use to the next:
        at 10k bodies, re-setting the swapped arguments of shared recorded launches cost ~1 ms a
        step of Python (launch.py's set_param_at_index, ~4 us each)."""
        sites = self._sites.get(state)
        if sites is None:
            sites = self._sites[state] = {}
        site = sites.get(name)
        if site is None:
            site = sites[name] = _LaunchSite()
        return site

    def _make_rows(self) -> int:
        if self.reuse_terrain_rows and not getattr(self, "_rebuild_rows", False):
            return MAKE_ROWS
        return MAKE_ROWS_ALWAYS

    def _split_overflow(self) -> bool:
        """Whether the pairs past the colours are swept with split masses (pair_overflow.py says
        when each way pays) or walked in order by one thread."""
        choice = self.settings.overflow_pairs
        return choice == "split" or (choice == "auto" and self.device.is_cuda)

    def _overflow_pairs(self, m) -> OverflowPairs:
        """The overflow set's scratch, made by the first colour-scheduled step (the first step
        of a captured simulation runs directly, so before any capture)."""
        if getattr(self, "_overflow", None) is None:
            self._overflow = OverflowPairs(m.body_count, self.device)
        return self._overflow

    def _prepare(self, m, a, fresh_contacts: bool, make_rows: bool, from_impact: bool):
        launch(prepare_bodies, m.body_count, key=self, inputs=[
            a.model, a.settings, int(fresh_contacts), self._make_rows() if make_rows else MAKE_ROWS_NONE,
            int(from_impact), a.state_in, a.slots, a.solver], device=self.device)

    def _integrate_positions(self, m, a):
        launch(integrate_positions, m.body_count, key=self, inputs=[
            a.model, a.settings, a.state_in, a.solver, a.state_out], device=self.device)

    def _step_fused(self, model, a):
        launch(solve_and_integrate, dim=model.body_count, key=self, inputs=[
            a.model, a.settings, a.slots, *self._impact_scratch(a.contacts), a.state_in, a.state_out,
            a.bad_steps], device=self.device)

    def _finalize(self, m, a):
        launch(finalize_bodies, m.body_count, key=self, min_chunk=LIGHT_CHUNK, inputs=[
            a.model, a.settings, a.state_in, a.solver, a.state_out, a.bad_steps], device=self.device)

    def runs_impacts(self, m) -> bool:
        """Whether the substep has an impact stage: in a scene with restitution, or in every scene
        with ``impacts = "always"`` (an inelastic scene's impacts are then converged apart from the
        soft solve, whose few sweeps leave friction and normal impulses coupled through a body's
        turn unconverged: a cube tripping with friction on a step kept 1.1 % too much angular
        momentum about the edge; tests/test_impacts.py)."""
        return m.has_restitution or self.settings.impacts == "always"

    def _impact_begin(self, m, a, fresh_contacts):
        """The impact stage's start (impact.py): the velocities the last solve left, without this
        substep's gravity.  Run where runs_impacts says."""
        launch(impact_begin, m.body_count, key=self, inputs=[
            a.model, a.settings, int(fresh_contacts), a.state_in, a.solver, int(self.joint_impacts), a.joint],
               device=self.device)

    def _pair_contact_times(self, a):
        """Each body's earliest pair event of the substep, which shadows its later terrain
        impacts (impact.pair_contact_times); after the impact begin, before the impact sweeps.
        One launch, never split: Warp's CPU atomics are not atomic across chunks (launch.py)."""
        if a.contacts.pair_max > 0:
            wp.launch(pair_contact_times, dim=a.contacts.pair_max, device=self.device, **gpu_blocks(self.device), inputs=[
                0, a.model, a.settings, a.contacts.pair_count, a.pairs, a.solver, int(self.joint_impacts), a.joint])

    @property
    def joint_impacts(self) -> bool:
        """Whether the impact stage starts with the joint phase (impact_joint.py)."""
        return self.settings.simultaneous_impacts == "joint"

    def _impact_members(self, m, a):
        """Each body's terrain manifold closing at the stage's start, counted with its closing pairs
        (impact_joint.terrain_members); after the pairs' contact times."""
        launch(terrain_members, m.body_count, key=self, inputs=[a.model, a.settings, a.slots, a.solver, a.joint],
               device=self.device)

    def _impact_sweep(self, m, a, pairs, color_sizes, stage):
        """One impact round's sweeps (plan.impact_round_sweeps): every body's terrain impact, then the
        pairs' (colour by colour), numbered so that manifolds no impact has touched since are
        skipped (plan.impact_first_since).  The joint phase's rounds go to _joint_sweep."""
        for u in range(impact_round_sweeps(stage)):
            sweep = stage.index * IMPACT_INNER + u
            since = impact_first_since(stage, sweep - 1) if u == 0 else sweep - 1
            if stage.mode in JOINT_MODES:
                self._joint_sweep(m, a, color_sizes, stage.mode, sweep, since)
                continue
            launch(terrain_impact, m.body_count, key=self,
                   inputs=[a.model, a.settings, a.slots, a.solver, sweep, since], device=self.device)
            pairs(stage.mode, sweep, since)

    def _impacts_while_travelling(self, m, run_round, sweeps_of_round):
        """plan.IMPACT_TRAVEL: while the round before changed a body, plan.travel_rounds() again, at
        most TRAVEL_LOOPS times (impact.py).  ``run_round(stage)`` runs one round on the schedule
        at hand; ``sweeps_of_round(index)`` gives the first and last sweep numbers it stamps.
        The flag stays on the device (``wp.capture_while``); the check is one launch, never split
        (its atomics: launch.py)."""

        def check(index: int):
            first, last = sweeps_of_round(index)
            wp.launch(impacts_travelling, dim=m.body_count, device=self.device, **gpu_blocks(self.device),
                      inputs=[0, first, last, self.solver_impact_stamp, self.travelling])

        def loop():
            rounds = travel_rounds()
            for stage in rounds:
                run_round(stage)
            self.travelling.zero_()
            check(rounds[-1].index)
            wp.launch(count_travel_loop, dim=1, device=self.device,
                      inputs=[TRAVEL_LOOPS, self.travel_loops, self.travelling])

        self.travelling.zero_()
        self.travel_loops.zero_()
        check(travel_rounds()[0].index - 1)
        wp.capture_while(self.travelling, loop)

    def _joint_sweep(self, m, a, color_sizes, mode: int, sweep: int, since: int):
        """One sweep of the joint phase or its bounce on the colour schedule (impact_joint.py): the
        bodies' terrain members, then the member pairs colour by colour; the overflow pairs take
        their impacts in sequence only."""
        c = a.contacts
        launch(terrain_joint_impact, m.body_count, key=self,
               inputs=[mode, a.model, a.settings, a.slots, a.solver, a.joint, sweep, since], device=self.device)
        for color, size in enumerate(color_sizes[:COLOR_COUNT]):
            if size:
                launch(pair_joint_pass, size, key=self, min_chunk=PAIR_CHUNK, inputs=[
                    mode, sweep, since, color, c.color_start, c.color_pairs_sorted, a.model, a.settings, a.pairs,
                    a.solver, a.joint], device=self.device)

    def _step_staged(self, model, contacts, a, color_sizes, fresh_contacts, domains=None, after_impacts=None):
        if domains is not None:
            self._step_domains(model, a, fresh_contacts, domains, after_impacts)
            return
        s = self.settings
        m, c = model, contacts
        n = m.body_count
        dev = self.device

        overflow = self._overflow_pairs(m) if self._split_overflow() else None

        def terrain(use_bias: int):
            launch(terrain_sweep, n, key=self, inputs=[a.model, a.settings, use_bias, a.slots, a.solver],
                   device=dev)

        def pairs(mode: int, sweep: int = 0, since: int = -1):
            for color, size in enumerate(color_sizes):
                if size == 0:
                    continue
                if color == COLOR_COUNT and self._split_overflow():
                    # pairs that share bodies, swept at once with split masses (pair_overflow.py)
                    # recount at the substep's first pair stage after a colouring (impacts come first)
                    recount = mode == MODE_WARM_START or (mode == MODE_IMPACT
                                                          and sweep == FIRST_SEQUENTIAL_ROUND * IMPACT_INNER)
                    overflow.stage(mode, overflow.threads(size), recount, c, m.body_inv_mass, a.model, a.settings,
                                   a.pairs, a.solver, self.solver_v, self.solver_w, sweep, since)
                    if mode == MODE_SOLVE and m.has_mass_ratio:
                        launch(chain_pass, 1, key=self, inputs=[
                            mode, color, c.color_start, c.color_pairs_sorted, a.model, a.settings, a.pairs, a.slots,
                            a.solver], device=dev)
                    continue
                dim = 1 if color == COLOR_COUNT else size
                launch(PAIR_PASS[mode], dim, key=self, min_chunk=PAIR_CHUNK, inputs=[
                    sweep, since, color, c.color_start, c.color_pairs_sorted, a.model, a.settings, a.pairs,
                    a.solver], device=dev)
                # the heavy-on-light passes after a solve; after a relax the walk to the ground, which
                # relax_passes = 1 never takes (pair_solve.relax_chain_needed)
                if (mode == MODE_SOLVE and m.has_mass_ratio) or (mode in RELAX_MODES and m.checkpoint_count > 0
                                                                and s.relax_passes > 1):
                    launch(chain_pass, dim, key=self, min_chunk=PAIR_CHUNK, inputs=[
                        mode, color, c.color_start, c.color_pairs_sorted, a.model, a.settings, a.pairs, a.slots,
                        a.solver], device=dev)

        plan = substep_plan(s.iterations, s.relax_iterations, self.runs_impacts(m), self.joint_impacts)

        def impact_round(stage):
            self._impact_sweep(m, a, pairs, color_sizes, stage)

        def colour_sweeps(index: int):  # the sweep numbers of one round (_impact_sweep)
            return index * IMPACT_INNER, index * IMPACT_INNER + IMPACT_INNER - 1

        def sequential_impact_sweeps():
            for stage in plan:
                if stage.kind == IMPACT and stage.mode == MODE_IMPACT:
                    impact_round(stage)
                elif stage.kind == IMPACT_TRAVEL:
                    self._impacts_while_travelling(m, impact_round, colour_sweeps)

        def impacts_again(sizes):
            nonlocal color_sizes
            color_sizes = sizes
            self._pair_contact_times(a)
            sequential_impact_sweeps()

        for stage in plan:
            kind = stage.kind
            if kind == IMPACT_BEGIN:
                self._impact_begin(m, a, fresh_contacts)
                self._pair_contact_times(a)
                if self.joint_impacts:
                    self._impact_members(m, a)
            elif kind == IMPACT:
                self._impact_sweep(m, a, pairs, color_sizes, stage)
            elif kind == IMPACT_TRAVEL:
                self._impacts_while_travelling(m, impact_round, colour_sweeps)
            elif kind == AFTER_IMPACTS:
                if after_impacts is not None:
                    color_sizes = after_impacts(impacts_again)
            elif kind == PREPARE:
                self._prepare(m, a, fresh_contacts, True, self.runs_impacts(m))
            elif kind == WARM_START:
                pairs(stage.mode)
            elif kind == SOLVE or kind == RELAX:
                terrain(stage.use_bias)
                pairs(stage.mode)
            elif kind == INTEGRATE:
                self._integrate_positions(m, a)
            elif kind == FINALIZE:
                self._finalize(m, a)

    def _step_domains(self, m, a, fresh_contacts, g, after_impacts=None):
        """The staged soft step swept slab by slab (solvers/domains.py).

        Symmetric Gauss-Seidel: the second solve sweep walks back over the first, and the relax
        sweep goes on backwards, so neither end of the body order is favoured.  Measured (stack of
        10 built bottom-up and top-down, pyramid of base 10; F forward, B backward): F F F: the
        stack still sagged 9 % past its static spring value after 1 s; B F B: the pyramid crept
        15 mm; F B F: the bottom-up stack 3 % past; F B B: within 0.5 % and 0.55 mm (colours:
        0.3 % and 0.8 mm).  With one solve sweep (``iterations = 1``) F B let 10 cubes drift 4
        to 34 mm sideways in 6 s (e 0 and 0.5, listed bottom-up and top-down), and B B 0.1 to
        0.35 mm: whatever the count, the last solve sweep walks backwards, its pairs first and
        the terrain rows last (plan.substep_plan).

        Each sweep is the slabs' launch, then the boundary pairs' (one thread).  The per-body stages
        ride on them instead of running as launches of their own, which saves three launches
        split over the cores per substep (~0.1 ms of thread hand-off each, launch.py): each slab
        thread prepares its bodies at the start of the first sweep; after the last solve sweep
        (relax sweep) it integrates (finalizes) those of its bodies that no boundary pair
        touches, and the boundary thread the rest, after the boundary pairs' sweep.  The order
        of the sweeps is unchanged by this (moving the boundary sweep first so that the slabs
        could finish every body themselves let a 10-box stack cut into slabs sag 9.2 mm instead
        of 6.9: two boundary sweeps in a row converge as one)."""
        s = self.settings
        dev = self.device
        impacts = self.runs_impacts(m)
        slabs = bind(DomainSlabs, self, g)
        shared = [slabs, a.model, a.settings, int(fresh_contacts), self._make_rows(), int(impacts), a.state_in,
                  a.slots, a.pairs, a.solver, a.state_out, a.bad_steps]
        state_in = a.buffer_in

        def sweep(mode: int, reverse: int, prepare: int = 0, integrate: int = 0, finalize: int = 0, impact=None):
            impact_round = impact.index if impact is not None else 0

            def since(boundary: int) -> int:  # of the round's first sweep (domains.impact_sweep_number)
                if impact is None:
                    return -1
                return impact_first_since(impact, ((2 * impact_round - 2 + boundary) + 1) * IMPACT_INNER - 1)

            kernel = DOMAIN_SWEEP[mode]
            launch(kernel, g.domain_count, [0, g.domain_count, reverse, prepare, integrate, finalize,
                                            impact_round, since(0), int(m.has_mass_ratio), *shared], dev,
                   key=self._site(state_in, "slabs", mode, reverse, prepare, integrate, finalize, impact_round),
                   min_chunk=1)
            if g.boundary_pairs:
                launch(kernel, 1, [g.domain_count, g.domain_count, reverse, 0, integrate, finalize,
                                   impact_round, since(1), int(m.has_mass_ratio), *shared], dev,
                       key=self._site(state_in, "boundary", mode, reverse, integrate, finalize, impact_round),
                       min_chunk=1)

        if g.static_bodies:
            launch(DOMAIN_SWEEP[MODE_WARM_START], 1, [g.domain_count + 1, g.domain_count, 0, 1, 1, 1, 0, -1, 0, *shared],
                   dev,
                   key=self._site(state_in, "static"), min_chunk=1)
        plan = substep_plan(s.iterations, s.relax_iterations, impacts, self.joint_impacts)
        # the per-body stages ride on the sweeps next to them (module docstring of plan.py)
        fused_with_solve = s.iterations > 0
        fused_with_relax = s.relax_iterations > 0

        def impact_round(stage):
            sweep(stage.mode, stage.reverse, impact=stage)

        def slab_sweeps(index: int):  # the sweep numbers of one round, slabs then boundary (domains.impact_sweep_number)
            return 2 * index * IMPACT_INNER, (2 * index + 2) * IMPACT_INNER - 1

        def impacts_again(_sizes):  # g's arrays and counts were updated in place by the pass
            self._pair_contact_times(a)
            for again in plan:
                if again.kind == IMPACT and again.mode == MODE_IMPACT:
                    impact_round(again)
                elif again.kind == IMPACT_TRAVEL:
                    self._impacts_while_travelling(m, impact_round, slab_sweeps)

        for stage in plan:
            kind = stage.kind
            if kind == IMPACT_BEGIN:
                # its own launch: the pairs' contact times read every body's impact velocities
                self._impact_begin(m, a, fresh_contacts)
                self._pair_contact_times(a)
            elif kind == IMPACT and stage.mode in JOINT_MODES:
                # the whole joint phase, one launch at its first round (impact_joint.joint_phase_in_order)
                if stage.index == 0:
                    launch(joint_phase_in_order, 1, [m.body_count, a.model, a.settings, a.slots, a.contacts.pair_count,
                                                     a.pairs, a.solver, a.joint], dev,
                           key=self._site(state_in, "joint"), min_chunk=1)
            elif kind == IMPACT:
                impact_round(stage)
            elif kind == IMPACT_TRAVEL:
                self._impacts_while_travelling(m, impact_round, slab_sweeps)
            elif kind == AFTER_IMPACTS:
                if after_impacts is not None:
                    after_impacts(impacts_again)
            elif kind == PREPARE and not fused_with_solve:
                self._prepare(m, a, fresh_contacts, True, impacts)
            elif kind == WARM_START and not fused_with_solve:
                sweep(stage.mode, 0)
            elif kind == SOLVE:
                sweep(stage.mode, stage.reverse, prepare=int(stage.first), integrate=int(stage.last))
            elif kind == INTEGRATE and not fused_with_solve:
                self._integrate_positions(m, a)
            elif kind == RELAX:
                sweep(stage.mode, stage.reverse, finalize=int(stage.last))
            elif kind == FINALIZE and not fused_with_relax:
                self._finalize(m, a)


class PushoutSolver(SoftStepSolver):
    """The thesis's contact response (SEED.md 3, pushout.py), kept as the baseline the soft step
    is measured against.  It shares the soft step's per-body stages (prepare, integrate,
    finalize) and arrays, and replaces the substep."""

    fused_in_place = False  # its push-out passes read other bodies' output positions

    def step(self, model, state_in, state_out, contacts, dt: float, body_bad_step, bad_count, color_sizes=None,
             fresh_contacts: bool = True, domains=None, rebuild_rows: bool = False, after_impacts=None):
        """One substep of the thesis's response (pushout.py): one impulse pass, integrate, then
        position push-out.  Contacts are found every substep and pairs are always coloured, so
        ``fresh_contacts``, ``domains``, ``rebuild_rows`` and ``after_impacts`` do not apply."""
        color_sizes = color_sizes or []
        s = self.settings
        m, c = model, contacts
        n = m.body_count
        dev = self.device
        a = self._args(model, state_in, state_out, contacts, dt, body_bad_step, bad_count)
        self._prepare(m, a, True, False, False)

        def pairs(position_pass: int):
            for color, size in enumerate(color_sizes):
                if size:
                    launch(pushout_pair, 1 if color == COLOR_COUNT else size, key=self, inputs=[
                        position_pass, color, c.color_start, c.color_pairs_sorted,
                        m.body_inv_mass, m.body_restitution, m.body_friction, state_in.body_pos,
                        c.pair_body, c.pair_point_count, c.pair_normal, c.pair_point, c.pair_depth,
                        self.solver_inv_inertia, self.solver_shift_v, self.solver_shift_w, self.solver_v,
                        self.solver_w, state_out.body_pos], device=dev)

        launch(pushout_terrain_impulse, n, key=self, inputs=[
            m.body_inv_mass, m.body_restitution, m.body_friction, m.body_checkpoint_start, m.body_checkpoint_count,
            state_in.body_pos, c.terrain_contact_active, c.terrain_contact_point, c.terrain_contact_normal,
            c.terrain_contact_depth, self.solver_inv_inertia, self.solver_v, self.solver_w], device=dev)
        pairs(0)
        self._integrate_positions(m, a)
        for _ in range(s.iterations):
            launch(pushout_terrain_position, n, key=self, inputs=[
                m.body_inv_mass, m.body_checkpoint_start, m.body_checkpoint_count, state_in.body_pos,
                c.terrain_contact_active, c.terrain_contact_point, c.terrain_contact_normal, c.terrain_contact_depth,
                self.solver_shift_v, self.solver_shift_w, state_out.body_pos], device=dev)
            pairs(1)
        launch(finalize_bodies, n, key=self, inputs=[
            a.model, a.settings, a.state_in, a.solver, a.state_out, a.bad_steps], device=dev)


def make_solver(settings: SolverSettings, gravity, device, body_count: int = 0) -> SoftStepSolver:
    """The solver ``settings.solver`` names: "soft_step" (default) or "pushout" (the baseline)."""
    kind = {"soft_step": SoftStepSolver, "pushout": PushoutSolver}[settings.solver]
    return kind(settings, gravity, device, body_count)
