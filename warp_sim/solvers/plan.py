"""The soft step's substep, written once: the stage sequence every pair schedule runs.

After Box2D v3's solver stages (one list, consumed by each scheduler).  One substep is

    [impact begin, pair contact times,                                 only with impacts
     JOINT_ROUNDS compression rounds and one bounce sweep of the impacts closing at the start
     (impact_joint.py; the slab schedule runs them as one launch at the first round),
     IMPACT_SWEEPS rounds of sequential impact sweeps (impact.py), then two more rounds at a time
     while a blow is still travelling (IMPACT_TRAVEL), after-impacts hook]
    prepare, warm start
    `iterations` solve sweeps (soft bias)
    integrate
    `relax_iterations` relax sweeps (no bias; closed contacts only with restitution)
    finalize

solver.py runs it colour by colour (the GPU schedule: one launch per stage, a sweep being the
terrain launch then one launch per colour) and slab by slab (the CPU schedule, solvers/domains.py,
which rides the per-body stages on the sweeps next to them: prepare and warm start on the first
solve sweep, integrate on the last solve sweep, finalize on the last relax sweep; the impact
begin is a launch of its own on both, as the pairs' contact times read it).  ``reverse`` is the walk order of a sweep where the schedule
has one (slabs: symmetric Gauss-Seidel, see SoftStepSolver._step_domains); colours have none.
The terrain-only fused kernel (soft_step.py) is the same sequence for one body, unrolled in one
kernel.
"""

from __future__ import annotations

from dataclasses import dataclass

from .impact import IMPACT_INNER, IMPACT_SWEEPS
from .impact_joint import JOINT_ROUNDS
from .pair_solve import (MODE_IMPACT, MODE_IMPACT_BOUNCE, MODE_IMPACT_JOINT, MODE_RELAX, MODE_RELAX_CLOSED, MODE_SOLVE,
                         MODE_WARM_START)

IMPACT_BEGIN, IMPACT, IMPACT_TRAVEL, AFTER_IMPACTS, PREPARE, WARM_START, SOLVE, INTEGRATE, RELAX, FINALIZE = range(10)
SWEEPS = (IMPACT, SOLVE, RELAX)
# the impact rounds, numbered through the stage: compression, bounce, then the sequential rounds,
# then the two rounds IMPACT_TRAVEL repeats
BOUNCE_ROUND = JOINT_ROUNDS
FIRST_SEQUENTIAL_ROUND = JOINT_ROUNDS + 1
TRAVEL_ROUND = FIRST_SEQUENTIAL_ROUND + IMPACT_SWEEPS
# IMPACT_TRAVEL's loop runs its two rounds at most this many times a substep (impact.py: a blow
# still travelling after them is stopped by the soft solve, inelastically)
TRAVEL_LOOPS = 16


@dataclass(frozen=True)
class Stage:
    kind: int
    index: int = 0  # which sweep of its kind this is
    count: int = 1  # how many sweeps of its kind the substep runs
    mode: int = MODE_WARM_START  # the pair_solve mode of a sweep (or of the warm start)
    use_bias: int = 0  # terrain rows: 1 soft bias, 0 none, -1 no bias and closed contacts only
    reverse: int = 0

    @property
    def first(self) -> bool:
        return self.index == 0

    @property
    def last(self) -> bool:
        return self.index == self.count - 1


def substep_plan(iterations: int, relax_iterations: int, impacts: bool, joint: bool = False) -> tuple[Stage, ...]:
    """The stages of one substep.  ``impacts``: the substep has an impact stage (SoftStepSolver.runs_impacts);
    a scene without runs no impact stage, and its relax sweeps close open gaps too.  ``joint``: the
    stage starts with the joint phase (SimConfig.simultaneous_impacts = "joint")."""
    plan = []
    if impacts:
        plan.append(Stage(IMPACT_BEGIN))
        if joint:
            plan += [Stage(IMPACT, k, JOINT_ROUNDS, MODE_IMPACT_JOINT, reverse=k % 2) for k in range(JOINT_ROUNDS)]
            plan.append(Stage(IMPACT, BOUNCE_ROUND, 1, MODE_IMPACT_BOUNCE))
        plan += [Stage(IMPACT, FIRST_SEQUENTIAL_ROUND + k, IMPACT_SWEEPS, MODE_IMPACT, reverse=k % 2)
                 for k in range(IMPACT_SWEEPS)]
        plan.append(Stage(IMPACT_TRAVEL, TRAVEL_ROUND, mode=MODE_IMPACT))
        plan.append(Stage(AFTER_IMPACTS))
    plan += [Stage(PREPARE), Stage(WARM_START)]
    # the sweeps alternate direction and the last one walks backwards, ending on the terrain rows
    # (SoftStepSolver._step_domains gives the measurements)
    plan += [Stage(SOLVE, k, iterations, MODE_SOLVE, use_bias=1, reverse=(k + iterations) % 2)
             for k in range(iterations)]
    plan.append(Stage(INTEGRATE))
    # relax: open gaps of a scene with restitution are left to the next substep's impact stage
    relax_mode, relax_bias = (MODE_RELAX_CLOSED, -1) if impacts else (MODE_RELAX, 0)
    plan += [Stage(RELAX, k, relax_iterations, relax_mode, use_bias=relax_bias, reverse=1)
             for k in range(relax_iterations)]
    plan.append(Stage(FINALIZE))
    return tuple(plan)


def travel_rounds() -> tuple[Stage, Stage]:
    """The two sequential rounds IMPACT_TRAVEL repeats, in opposite directions (a round's numbers
    follow every fixed round's, so plan.impact_first_since can tell them)."""
    return (Stage(IMPACT, TRAVEL_ROUND, 2, MODE_IMPACT, reverse=0), Stage(IMPACT, TRAVEL_ROUND + 1, 2, MODE_IMPACT, reverse=1))


def impact_round_sweeps(stage: Stage) -> int:
    """Sweeps an impact round runs: one for the bounce (each member bounces once), else IMPACT_INNER."""
    return 1 if stage.mode == MODE_IMPACT_BOUNCE else IMPACT_INNER


def impact_first_since(stage: Stage, previous_sweep: int) -> int:
    """The ``since`` of an impact round's first sweep (impact.unchanged_since): -1, every manifold
    taken, in the first round of each phase: the joint phase's (each closing manifold's t*:
    impact_joint.py) and the sequential one's (the manifolds the joint phase left, and a repeat for
    the pairs found after the impacts), and IMPACT_TRAVEL's first round (its loop replays the same
    sweep numbers, so stamps of the last pass may read newer than the sweep at hand: taking every
    manifold then is always right); else ``previous_sweep``, the sweep in which the same launch
    last took its manifolds."""
    if stage.index in (0, FIRST_SEQUENTIAL_ROUND, TRAVEL_ROUND):
        return -1
    return previous_sweep
