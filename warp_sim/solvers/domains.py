"""Spatial domains: how the staged solver uses every CPU core without colouring.

Graph colouring (schedule/coloring.py) makes a sweep parallel by splitting it into one launch per colour.
On a GPU that is the right trade.  On a CPU each launch that is split across cores pays a thread
hand-off (~90 us here, warp_sim/launch.py), and a colour of a few thousand pairs runs in about
that time: at 10k bodies the six or so colours of a sweep each ran on one core, and the pair
sweeps cost 15 ms of a 53 ms step.

Instead, cut the scene into D slabs (D = CPU threads) along its longer horizontal axis, with
equal solver work in each (work = 1 + active terrain contacts + contact points of a body).  A
pair whose dynamic bodies lie in one slab belongs to that slab; a pair across a cut is a
boundary pair.  One sweep is then

    D threads at once: each walks its slab's bodies (terrain contacts) then its pairs, in order
    one thread:        the boundary pairs, in order

No two threads touch one body in the first stage (a body is in one slab; static bodies are
never written), so there is no race, and each slab's sweep is plain sequential Gauss-Seidel,
which converges at least as fast as the coloured order.  Only the pairs across the D - 1 cuts
wait for the second stage: a few percent of the pairs in a pile.  Two launches per sweep instead
of one per colour plus one for the terrain.

The per-body stages of a substep ride on the sweep launches instead of paying hand-offs of
their own (solver.py, _step_domains): a slab thread prepares its bodies and warm-starts its
pairs at the start of the first sweep (its side of each boundary pair too: a warm start moves
each body by its own share only, see pair_solve.warm_start_pair_side); after the last solve
sweep it integrates, and after the relax sweep finalizes, its bodies that no boundary pair
touches, and the boundary thread does the others once their pairs are swept.  The static
bodies, listed after the slabs, are prepared, integrated and finalized (copied) by one thread
before the sweeps (domain_sweep with d = D + 1).

The slabs themselves are cut by warp_sim/schedule/slabs.py, once per collision pass.
"""

import warp as wp

from ..kernel_args import BadSteps, BodyModel, BodyState, PairContacts, TerrainContacts
from .impact import IMPACT_INNER, impact_terrain_body
from .pair_solve import (MODE_IMPACT, MODE_RELAX, MODE_RELAX_CLOSED, MODE_SOLVE, MODE_WARM_START,
                         SWEEP_MODE_NAMES, chain_pair, pair_normal_total, relax_chain_needed, relax_chain_pair,
                         solve_one_pair, warm_start_pair_side)
from .solver_args import DomainSlabs, SolverBodies, StepSettings
from .staged import finalize_body, integrate_body, prepare_body, sweep_body_terrain

wp.set_module_options({"enable_backward": False})

@wp.func
def walk(first: int, count: int, k: int, reverse: int) -> int:
    """The k-th index of [first, first + count), from the end when ``reverse``."""
    if reverse != 0:
        return first + count - 1 - k
    return first + k


@wp.func
def impact_sweep_number(impact_round: int, boundary: int, u: int) -> int:
    """The number of the u-th impact sweep of a round: a round runs IMPACT_INNER slab sweeps, then
    IMPACT_INNER boundary sweeps (``boundary`` 1), each launch looping over its own."""
    return (2 * impact_round + boundary) * IMPACT_INNER + u


@wp.func
def impact_sweep_since(impact_round: int, boundary: int, u: int, first_since: int) -> int:
    """The sweep in which the same launch kind last took its manifolds (impact.unchanged_since):
    the one before within a launch; for a launch's first, ``first_since`` (plan.impact_first_since)."""
    if u > 0:
        return impact_sweep_number(impact_round, boundary, u - 1)
    return first_since


@wp.func(inline=True)
def solve_pair_in_slab(
    p: int,
    mode: int,
    has_mass_ratio: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in/out
    pairs: PairContacts,
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
    sweep: int,
    since: int,
):
    """Pair p in a slab's (or the boundary's) sweep, with the passes that follow it: the heavy-on-light
    chain after a solve, the chain to the ground after a relax that let go of a push (pair_solve).  Inlined:
    a func the C++ compiler does not inline gets the argument structs by value, a few kB a call."""
    relax = mode == MODE_RELAX or mode == MODE_RELAX_CLOSED
    held = float(0.0)
    if relax:
        held = pair_normal_total(p, pairs)
    solve_one_pair(p, mode, model, settings, pairs, solver, sweep, since)
    if mode == MODE_SOLVE and has_mass_ratio != 0:
        chain_pair(p, model, settings, pairs, slots, solver)
    if relax and relax_chain_needed(p, held, model, settings, pairs, solver) != 0:
        relax_chain_pair(p, mode, model, settings, pairs, slots, solver)


# One kernel per sweep mode, the mode a compile-time constant.  A kernel taking the mode as an
# argument carries every mode's code (impacts, the relax's walks, the warm start) into each sweep,
# and the compiler, unable to drop any of it, lays out registers and stack for all of it; with the
# mode fixed the other modes' branches fold away.  Same arithmetic, so the same results bit for
# bit; the solve sweeps of the 10k rain run faster (bench/results/versions_sweep_modes.*, README).


def domain_sweep_for(mode: int):
    """The slab sweep of pair_solve mode ``mode`` (one of pair_solve.SWEEP_MODE_NAMES)."""

    @wp.kernel(name="domain_sweep_" + SWEEP_MODE_NAMES[mode])
    def domain_sweep(
        tid_offset: int,
        first_domain: int,
        domain_count: int,
        reverse: int,
        prepare: int,
        integrate: int,
        finalize: int,
        impact_round: int,
        impact_since: int,
        has_mass_ratio: int,
        # In
        slabs: DomainSlabs,
        # Model
        model: BodyModel,
        # Settings
        settings: StepSettings,
        reset_reference: int,
        make_rows: int,
        from_impact: int,
        # State in
        state_in: BodyState,
        # Contacts in/out
        slots: TerrainContacts,
        pairs: PairContacts,
        # Solver in/out
        solver: SolverBodies,
        # State out
        state_out: BodyState,
        # Out
        bad_steps: BadSteps,
    ):
        """One sweep of one slab (d < domain_count: its bodies' terrain contacts, then its pairs) or of
        the boundary pairs (d == domain_count), in the pair_solve mode ``mode`` (fixed at compile
        time); ``reverse`` walks the same sequence backwards (symmetric Gauss-Seidel, see the module
        docstring).

        The per-body stages ride on the sweeps (see the module docstring): with ``prepare`` a slab
        thread first prepares its bodies (prepare_body) and applies the warm start of its pairs and
        of its side of the boundary pairs; with ``integrate`` or ``finalize`` it integrates or
        finalizes, after its sweep, its bodies that no boundary pair touches, and the boundary thread
        the others after the boundary sweep.  d == domain_count + 1 runs all three stages for the
        static bodies."""
        d = first_domain + wp.tid() + tid_offset
        if d > domain_count:
            # the static bodies (listed after the slabs), before any sweep: the sweeps read their solver
            # state but never write it, and no slab owns them
            first = slabs.domain_body_start[domain_count]
            for k in range(slabs.domain_body_start[domain_count + 1] - first):
                i = slabs.domain_body[first + k]
                prepare_body(i, model, settings, reset_reference, make_rows, from_impact, state_in, slots, solver)
                integrate_body(i, model, settings, state_in, solver, state_out)
                finalize_body(i, model, settings, state_in, solver, state_out, bad_steps)
            return
        pair_first = slabs.domain_pair_start[d]
        pair_count = slabs.domain_pair_start[d + 1] - pair_first
        if d == domain_count:
            # impacts: IMPACT_INNER sweeps a launch, numbered after the slabs' of the same round
            inner = wp.where(mode == MODE_IMPACT, IMPACT_INNER, 1)
            for u in range(inner):
                sweep = impact_sweep_number(impact_round, 1, u)
                since = impact_sweep_since(impact_round, 1, u, impact_since)
                direction = wp.where(u % 2 == 1, 1 - reverse, reverse)
                for q in range(pair_count):
                    p = slabs.domain_pair[walk(pair_first, pair_count, q, direction)]
                    solve_pair_in_slab(p, mode, has_mass_ratio, model, settings, pairs, slots, solver, sweep, since)
            for k in range(slabs.boundary_body_count[0]):
                i = slabs.boundary_body[k]
                if integrate != 0:
                    integrate_body(i, model, settings, state_in, solver, state_out)
                if finalize != 0:
                    finalize_body(i, model, settings, state_in, solver, state_out, bad_steps)
            return
        body_first = slabs.domain_body_start[d]
        body_count = slabs.domain_body_start[d + 1] - body_first
        if prepare != 0:
            for k in range(body_count):
                prepare_body(slabs.domain_body[body_first + k], model, settings, reset_reference, make_rows,
                             from_impact,
                             state_in, slots, solver)
            for k in range(pair_count):
                solve_one_pair(slabs.domain_pair[pair_first + k], MODE_WARM_START, model, settings, pairs, solver, 0,
                               -1)
            # this slab's side of each boundary pair: before any sweep, like the pairs inside (a
            # boundary impulse applied after the first sweep let a stack split across two slabs sag
            # 27 mm instead of 7)
            boundary_first = slabs.domain_pair_start[domain_count]
            for q in range(slabs.domain_pair_start[domain_count + 1] - boundary_first):
                p = slabs.domain_pair[boundary_first + q]
                ij = pairs.pair_body[p]
                for side in range(2):
                    if slabs.body_domain[ij[side]] == d:
                        warm_start_pair_side(p, side, reset_reference, model, state_in, pairs, solver)
        terrain = mode == MODE_SOLVE or mode == MODE_RELAX or mode == MODE_RELAX_CLOSED
        use_bias = int(mode == MODE_SOLVE)
        if mode == MODE_RELAX_CLOSED:
            use_bias = -1
        # forward: terrain, then pairs; backward: the same sequence walked from its end.  Impacts run
        # IMPACT_INNER such sweeps a launch, alternating, so a chain of impacts inside a slab (a body
        # falling on a pile) is carried through in one launch; sweep numbers let a manifold whose bodies
        # no impact has changed since it was last taken be skipped (impact.unchanged_since)
        inner = wp.where(mode == MODE_IMPACT, IMPACT_INNER, 1)
        for u in range(inner):
            sweep = impact_sweep_number(impact_round, 0, u)
            since = impact_sweep_since(impact_round, 0, u, impact_since)
            direction = wp.where(u % 2 == 1, 1 - reverse, reverse)
            for part in range(2):
                if (part == 0) == (direction == 0):
                    if mode == MODE_IMPACT:
                        for k in range(body_count):
                            impact_terrain_body(slabs.domain_body[walk(body_first, body_count, k, direction)], model,
                                                settings, slots, solver, sweep, since)
                    elif terrain:
                        for k in range(body_count):
                            sweep_body_terrain(slabs.domain_body[walk(body_first, body_count, k, direction)], model,
                                               settings, use_bias, slots, solver)
                else:
                    for k in range(pair_count):
                        p = slabs.domain_pair[walk(pair_first, pair_count, k, direction)]
                        solve_pair_in_slab(p, mode, has_mass_ratio, model, settings, pairs, slots, solver, sweep, since)
        if integrate != 0 or finalize != 0:
            for k in range(body_count):
                i = slabs.domain_body[body_first + k]
                if slabs.body_on_boundary[i] != 0:
                    continue  # a boundary pair moves it after this launch: the boundary thread does it
                if integrate != 0:
                    integrate_body(i, model, settings, state_in, solver, state_out)
                if finalize != 0:
                    finalize_body(i, model, settings, state_in, solver, state_out, bad_steps)

    return domain_sweep


DOMAIN_SWEEP = {mode: domain_sweep_for(mode) for mode in SWEEP_MODE_NAMES}
