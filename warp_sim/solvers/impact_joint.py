"""Simultaneous impacts: the manifolds that close at the impact stage's start are one impact.

Taken one after another (impact.py's sweeps, in pair order), a ball dropped onto the seam of two
touching balls gave the first pair the whole blow: the striker left 0.65 m/s sideways (e = 1)
and one lower ball took twice the other's speed; a ball dropped into a V-groove bounced off one
face only.  Any offset between the two contact times makes that sequence right, which side
depending on which is touched first; but a symmetric scene is exactly simultaneous, and within
one substep the offset cannot be told.  So the stage starts with Poisson's hypothesis over the
union of the manifolds that close on the stage's start velocities from an open gap (each at its
own t* > 0: ones the sequential stage's first sweep would strike; impact.pair_contact_times and
mark_terrain_member mark and count them) and share a dynamic body with another (``member``; a
closing manifold alone on its bodies gets the same answer from the sequential sweeps, which take
it):

    compression: P_c >= 0 at every engaged point of every member, no engaged point approaching,
                 P_c . v_n = 0   (projected Gauss-Seidel over the members, the impulses kept
                 from sweep to sweep: JOINT_ROUNDS rounds of IMPACT_INNER sweeps)
    restitution: P_r = e P_c at every point, each member with its own e (one bounce sweep)
    friction:    Coulomb on (1 + e) P_c, per member, after its restitution

For frictionless members v_c is the M-metric projection of v- onto the velocities that approach
at no engaged point (unique even when P_c is not), so a symmetric blow gives a symmetric result
and |v+|^2_M = (1 - e^2) |v_c|^2_M + e^2 |v-|^2_M: kinetic energy kept for e = 1, lost otherwise
(impact.py's identity, now over the union).  Each member's rows are taken at its own t*, at the
pose the start velocities carry the bodies to (they are not revised while the compression
converges), and each member's impulses shift its bodies by t* dv (impact.py says why).

Why an open gap: a contact already touching and still closing at the stage's start is a pile's
contact pressed through a chain, and compressing a pile's such contacts together is a diffusion
that the sweeps leave unconverged; the bounce of an unconverged P_c left a ball and a box below it
approaching at 0.6 m/s in the shipped mixed rain (seed 19), 11.5 mm into each other by the step's
end.  Those contacts are taken in sequence, as before.

"At once" is within one substep: contacts that close in successive substeps are successive
impacts, so a symmetric scene whose contacts meet exactly at a substep's end can have float32's
rounding of its positions (1e-8) put one of them in the next substep and take it in sequence.

What the members set off is then taken in sequence (impact.py): a contact that was not closing at
the start, such as the next ball of a row struck at one end, is a later event, so a row of
touching balls still carries a blow as Newton's cradle does.  The split overflow pairs
(pair_overflow.py) are never members: they are taken in sequence only.
"""

import warp as wp

from ..kernel_args import BodyModel, PairContacts, TerrainContacts
from ..schedule.coloring import color_range
from .impact import CLOSING, IMPACT_INNER, NOT_MEMBER, OTHER_EVENT, unchanged_since
from .impact_pair import (PairManifold, compress_pair, pair_engagement, pair_impact_friction, pair_manifold_at,
                          restitute_pair)
from .impact_point import free_fall_share
from .impact_terrain import IMPACT_SPEED_TOLERANCE, NOT_ENGAGED, compress_terrain, restitute_terrain, terrain_engagement
from .solver_args import JointImpacts, SolverBodies, StepSettings

wp.set_module_options({"enable_backward": False})

# The impact stage's phases, as pair_solve's modes: the sequential sweeps (impact.py), the
# members' compression, their restitution and friction.
IMPACT_SEQUENTIAL = 3
IMPACT_JOINT = 5
IMPACT_BOUNCE = 6
# Rounds of IMPACT_INNER compression sweeps on the colour schedule (the slab schedule sweeps as many
# at most, in one thread: joint_phase_in_order).  Two members sharing a body converge as the
# coupling of their rows through it (a ball in a 20-degree V: the cosine of the faces' angle,
# 0.77; a ball struck onto the seam of two 3 kg balls: 0.375): Gauss-Seidel on two coupled rows
# takes the error by its square a sweep, so 24 sweeps leave the V-groove 0.59 ** 24 = 3e-6 of the
# blow, and a pile, whose blow spreads like a diffusion, what 24 sweeps reach.  A member whose bodies
# no impulse has changed since its last sweep is skipped, so the sweeps cost only where the
# compression is still moving.
JOINT_ROUNDS = 6


@wp.func
def shares_a_body(i: int, j: int, joint: JointImpacts) -> bool:
    """Whether a closing manifold of bodies i and j shares a dynamic body with another: only then
    does the joint phase differ from the sequential one, which takes the others (impact.py)."""
    return wp.max(joint.impact_member_count[i], joint.impact_member_count[j]) >= 2


@wp.func
def gravity_by(i: int, toi: float, model: BodyModel, settings: StepSettings, solver: SolverBodies) -> wp.vec3:
    """What gravity has added to body i's velocity by t* (its share its contacts do not hold)."""
    return (free_fall_share(model.body_inv_mass[i], solver.solver_support[i]) * toi) * settings.gravity


@wp.func(inline=True)
def member_at(
    p: int,
    toi: float,
    acc: wp.vec4,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pairs: PairContacts,
    # Solver in
    solver: SolverBodies,
    joint: JointImpacts,
) -> PairManifold:
    """Member p's rows at its t*, at the pose the stage's start velocities carry the bodies to, with
    its impulses ``acc`` and the bodies' current velocities grown by gravity by t* (the impact acts
    there, as impact.impact_pair_velocity's)."""
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    m = pair_manifold_at(p, toi, model, pairs, solver, joint.impact_v_start[i], joint.impact_w_start[i],
                         joint.impact_v_start[j], joint.impact_w_start[j], solver.solver_drift_p[i],
                         solver.solver_drift_p[j], acc)
    m.vi = solver.solver_v[i] + gravity_by(i, toi, model, settings, solver)
    m.wi = solver.solver_w[i]
    m.vj = solver.solver_v[j] + gravity_by(j, toi, model, settings, solver)
    m.wj = solver.solver_w[j]
    return m


@wp.func(inline=True)
def store_member(
    p: int,
    toi: float,
    m: PairManifold,
    stamp: bool,
    last_event: bool,
    impact_sweep: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
):
    """Member p's new velocities (less gravity by t*) and position shifts t* dv on its dynamic bodies
    (a static body may sit in many pairs of one colour); with ``stamp`` the sweep's stamp, with
    ``last_event`` the pair as each one's last event (impact.pair_event_start)."""
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    if model.body_inv_mass[i] > 0.0:
        gi = gravity_by(i, toi, model, settings, solver)
        solver.solver_toi_shift[i] = solver.solver_toi_shift[i] + toi * ((solver.solver_v[i] + gi) - m.vi)
        solver.solver_v[i] = m.vi - gi
        solver.solver_w[i] = m.wi
        if stamp:
            solver.solver_impact_stamp[i] = impact_sweep
        if last_event:
            solver.solver_event_time[i] = toi
            solver.solver_event_partner[i] = j
    if model.body_inv_mass[j] > 0.0:
        gj = gravity_by(j, toi, model, settings, solver)
        solver.solver_toi_shift[j] = solver.solver_toi_shift[j] + toi * ((solver.solver_v[j] + gj) - m.vj)
        solver.solver_v[j] = m.vj - gj
        solver.solver_w[j] = m.wj
        if stamp:
            solver.solver_impact_stamp[j] = impact_sweep
        if last_event:
            solver.solver_event_time[j] = toi
            solver.solver_event_partner[j] = i


@wp.func
def joint_pair(
    p: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    joint: JointImpacts,
    impact_sweep: int,
    impact_since: int,
) -> int:
    """A compression sweep's visit of pair p.  The phase's first sweep (``impact_since`` < 0) finds
    a closing pair's t* and e on the stage's start velocities (impact.pair_contact_times marked it
    closing) where it shares a body with another closing manifold, and leaves the rest to the
    sequential sweeps."""
    event = joint.impact_pair_event[p]
    if impact_since < 0:
        if event[0] != CLOSING[0]:
            return 0
    elif event[0] < 0.0:
        return 0
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    count = pairs.pair_point_count[p]
    inv_mi = model.body_inv_mass[i]
    inv_mj = model.body_inv_mass[j]
    if impact_since < 0 and not shares_a_body(i, j, joint):
        joint.impact_pair_event[p] = NOT_MEMBER
        return 0
    acc = wp.vec4(NOT_ENGAGED)
    if impact_since < 0:
        engagement = pair_engagement(p, model, settings, pairs, solver, joint.impact_v_start[i], joint.impact_w_start[i],
                                     joint.impact_v_start[j], joint.impact_w_start[j], inv_mi, inv_mj,
                                     solver.solver_drift_p[i], solver.solver_drift_p[j], 0.0)
        pairs.pair_passes_clear[p] = engagement.clear
        if engagement.hit == 0:
            joint.impact_pair_event[p] = NOT_MEMBER
            return 0
        e = wp.max(model.body_restitution[i], model.body_restitution[j])
        event = wp.vec2(engagement.toi, wp.where(engagement.bounces == 0, 0.0, e))
        acc = engagement.acc
        joint.impact_pair_event[p] = event
    else:
        stamps = solver.solver_impact_stamp
        if unchanged_since(stamps[i], impact_since) and unchanged_since(stamps[j], impact_since):
            return 0
        acc = joint.impact_pair_acc[p]
    toi = event[0]
    m = member_at(p, toi, acc, model, settings, pairs, solver, joint)
    before = m.acc
    m = compress_pair(m, count, inv_mi, inv_mj, solver.solver_inv_inertia[i], solver.solver_inv_inertia[j])
    joint.impact_pair_acc[p] = m.acc
    moved = float(0.0)  # the most normal speed this visit changed at a point (the stamp's test)
    for k in range(count):
        moved = wp.max(moved, (inv_mi + inv_mj) * wp.abs(m.acc[k] - before[k]))
    stamp = impact_since < 0 or moved >= IMPACT_SPEED_TOLERANCE
    store_member(p, toi, m, stamp, False, impact_sweep, model, settings, pairs, solver)
    return wp.where(stamp, 1, 0)


@wp.func
def bounce_pair(
    p: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    joint: JointImpacts,
    impact_sweep: int,
) -> int:
    """A member's restitution, e P_c at each point, and its friction; the membership is spent."""
    event = joint.impact_pair_event[p]
    if event[0] < 0.0:
        return 0
    joint.impact_pair_event[p] = NOT_MEMBER
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    count = pairs.pair_point_count[p]
    inv_mi = model.body_inv_mass[i]
    inv_mj = model.body_inv_mass[j]
    inv_ii = solver.solver_inv_inertia[i]
    inv_ij = solver.solver_inv_inertia[j]
    toi = event[0]
    e = event[1]
    m = member_at(p, toi, joint.impact_pair_acc[p], model, settings, pairs, solver, joint)
    m = restitute_pair(m, count, e, inv_mi, inv_mj, inv_ii, inv_ij)
    mu = wp.sqrt(model.body_friction[i] * model.body_friction[j])
    if mu > 0.0:
        m = pair_impact_friction(m, count, e, mu, inv_mi, inv_mj, inv_ii, inv_ij)
    store_member(p, toi, m, True, True, impact_sweep, model, settings, pairs, solver)
    return 1


@wp.func
def joint_terrain_body(
    i: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
    joint: JointImpacts,
    impact_sweep: int,
    impact_since: int,
) -> int:
    """A compression sweep's visit of body i's terrain manifold (as joint_pair's of a pair; the
    engagement, found by terrain_members, is kept in impact_normal)."""
    event = joint.impact_terrain_event[i]
    if event[0] < 0.0:
        return 0
    if impact_since < 0 and joint.impact_member_count[i] < 2:
        joint.impact_terrain_event[i] = NOT_MEMBER
        return 0
    if impact_since >= 0 and unchanged_since(solver.solver_impact_stamp[i], impact_since):
        return 0
    start = model.body_checkpoint_start[i]
    count = model.body_checkpoint_count[i]
    x = solver.solver_ref_pos[i]
    inv_mass = model.body_inv_mass[i]
    toi = event[0]
    v = solver.solver_v[i] + toi * settings.gravity
    compressed = compress_terrain(start, count, x, v, solver.solver_w[i], inv_mass, solver.solver_inv_inertia[i],
                                  slots.terrain_contact_point, slots.terrain_contact_normal, solver.impact_normal)
    solver.solver_v[i] = compressed.v - toi * settings.gravity
    solver.solver_w[i] = compressed.w
    solver.solver_toi_shift[i] = solver.solver_toi_shift[i] + toi * (v - compressed.v)
    stamp = impact_since < 0 or compressed.hit != 0
    if stamp:
        solver.solver_impact_stamp[i] = impact_sweep
    return wp.where(stamp, 1, 0)


@wp.func
def mark_terrain_member(
    i: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
    joint: JointImpacts,
):
    """Body i's terrain manifold: a member (its t* and e) where it closes on the stage's start
    velocities, counted with the body's closing pairs (after impact.pair_contact_times, whose pair
    times shadow the terrain's as in the sequential sweeps)."""
    joint.impact_terrain_event[i] = NOT_MEMBER
    if model.body_inv_mass[i] == 0.0:
        return
    engagement = terrain_engagement(model.body_checkpoint_start[i], model.body_checkpoint_count[i],
                                    solver.solver_ref_pos[i], joint.impact_v_start[i], joint.impact_w_start[i],
                                    solver.solver_drift_p[i], solver.solver_drift_r[i], wp.vec3(0.0), settings.h,
                                    settings.gravity, settings.restitution_threshold, solver.solver_pair_toi[i],
                                    settings.soft[3], slots.terrain_contact_active, slots.terrain_contact_point,
                                    slots.terrain_contact_normal, slots.terrain_contact_depth, solver.impact_normal,
                                    solver.impact_tangent)
    if engagement.hit != 0 and engagement.toi > 0.0:
        joint.impact_terrain_event[i] = wp.vec2(engagement.toi,
                                                wp.where(engagement.bounces == 0, 0.0, model.body_restitution[i]))
        joint.impact_member_count[i] = joint.impact_member_count[i] + 1


@wp.kernel
def terrain_members(
    tid_offset: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
    joint: JointImpacts,
):
    # the colour schedule's launch of mark_terrain_member over the bodies (joint_phase_in_order calls it too)
    mark_terrain_member(wp.tid() + tid_offset, model, settings, slots, solver, joint)


@wp.func
def bounce_terrain_body(
    i: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
    joint: JointImpacts,
    impact_sweep: int,
) -> int:
    """Body i's terrain member's restitution and friction (as bounce_pair's)."""
    event = joint.impact_terrain_event[i]
    if event[0] < 0.0:
        return 0
    joint.impact_terrain_event[i] = NOT_MEMBER
    toi = event[0]
    v = solver.solver_v[i] + toi * settings.gravity
    bounced = restitute_terrain(model.body_checkpoint_start[i], model.body_checkpoint_count[i],
                                solver.solver_ref_pos[i], v, solver.solver_w[i], model.body_inv_mass[i],
                                solver.solver_inv_inertia[i], event[1], model.body_friction[i],
                                slots.terrain_contact_point, slots.terrain_contact_normal, solver.impact_normal,
                                solver.impact_tangent)
    solver.solver_v[i] = bounced.v - toi * settings.gravity
    solver.solver_w[i] = bounced.w
    solver.solver_toi_shift[i] = solver.solver_toi_shift[i] + toi * (v - bounced.v)
    solver.solver_impact_stamp[i] = impact_sweep
    solver.solver_event_partner[i] = OTHER_EVENT
    return 1


@wp.func
def pair_takes_part(event: wp.vec2, phase: int, impact_since: int) -> bool:
    """Whether a pair with this event has work in a sweep of the joint phase or its bounce: the
    phase's first sweep looks at the closing pairs (impact.pair_contact_times marked them), the
    later sweeps and the bounce at the members; a pair outside the phase returns here.  The joint
    functions live in kernels of their own: inlined into the sweep kernels, they slowed every mode
    of them (the slab kernel's sequential impact sweeps by 80 %).  A body's terrain manifold needs
    no such test beyond ``event[0] >= 0``: mark_terrain_member gives a closing one its t* at once."""
    if phase == IMPACT_JOINT and impact_since < 0:
        return event[0] == CLOSING[0]
    return event[0] >= 0.0


@wp.func(inline=True)
def joint_phase_pair(
    p: int,
    phase: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    joint: JointImpacts,
    impact_sweep: int,
    impact_since: int,
) -> int:
    """Pair p in a sweep of the joint phase (IMPACT_JOINT) or its bounce (IMPACT_BOUNCE); 1 where it
    changed its bodies (stamped them)."""
    if not pair_takes_part(joint.impact_pair_event[p], phase, impact_since):
        return 0
    if phase == IMPACT_JOINT:
        return joint_pair(p, model, settings, pairs, solver, joint, impact_sweep, impact_since)
    return bounce_pair(p, model, settings, pairs, solver, joint, impact_sweep)


@wp.kernel
def terrain_joint_impact(
    tid_offset: int,
    phase: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
    joint: JointImpacts,
    # In
    impact_sweep: int,
    impact_since: int,
):
    """Each body's terrain manifold in a sweep of the joint phase (IMPACT_JOINT) or its bounce, on
    the colour schedule (joint_phase_in_order takes them on the slab schedule)."""
    i = wp.tid() + tid_offset
    if joint.impact_terrain_event[i][0] < 0.0:
        return
    if phase == IMPACT_JOINT:
        joint_terrain_body(i, model, settings, slots, solver, joint, impact_sweep, impact_since)
    else:
        bounce_terrain_body(i, model, settings, slots, solver, joint, impact_sweep)


@wp.kernel
def pair_joint_pass(
    tid_offset: int,
    phase: int,
    impact_sweep: int,
    impact_since: int,
    color: int,
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
    joint: JointImpacts,
):
    """One colour's pairs in a sweep of the joint phase or its bounce: the colour schedule's
    pair_solve.pair_pass for the joint phase, a kernel of its own so that the joint code and its
    JointImpacts arrays stay out of the sweeps every scene runs (compiled into the slab sweep, they
    had slowed its other modes by half)."""
    r = color_range(color, color_start, wp.tid() + tid_offset)
    for index in range(r[0], r[1]):
        joint_phase_pair(color_pairs_sorted[index], phase, model, settings, pairs, solver, joint, impact_sweep, impact_since)


# The slab schedule's (the CPU's) joint phase, joint_phase_in_order: at most as many sweeps over the
# members as the colour schedule's rounds give, stopping at the first that moves no body.
IN_ORDER_SWEEPS = JOINT_ROUNDS * IMPACT_INNER


@wp.kernel
def joint_phase_in_order(
    tid_offset: int,
    body_count: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    slots: TerrainContacts,
    pair_count: wp.array(dtype=wp.int32),
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    joint: JointImpacts,
):
    """The whole joint phase on the slab schedule (the CPU's), in one thread: a walk over the bodies
    marks their closing terrain manifolds (mark_terrain_member), a second over them and the pairs finds the members (listed in impact_member_list: a pair as p, a
    body's terrain manifold as -(i + 1)) and takes their first sweep; then up to IN_ORDER_SWEEPS
    sweeps over the list alone, alternating direction, until one moves no body; then the bounce.

    Why not the slabs: the members of one impact in two slabs (one a boundary pair) met once a round
    of two launches, so rounds, not sweeps, bounded its convergence (4 rounds left a ball struck
    onto the seam of two 3 kg balls 1.1e-3 off in energy), and the 13 launches a substep of 6
    rounds, each handed between the cores, cost 0.16 ms each whatever the work: 8.5 ms a step of
    the shipped mixed rain at rest, 11 % of it.  Here the phase is one launch that runs on the
    calling thread; its serial work is a cheap walk over the bodies and pairs plus the members'
    own.  The colour schedule (CUDA) sweeps the members colour by colour in parallel instead."""
    for i in range(body_count):
        mark_terrain_member(i, model, settings, slots, solver, joint)
    count = int(0)
    for i in range(body_count):
        if joint.impact_terrain_event[i][0] >= 0.0:
            joint_terrain_body(i, model, settings, slots, solver, joint, 0, -1)
            if joint.impact_terrain_event[i][0] >= 0.0:
                joint.impact_member_list[count] = -(i + 1)
                count += 1
    for p in range(pair_count[0]):
        if pair_takes_part(joint.impact_pair_event[p], IMPACT_JOINT, -1):
            joint_pair(p, model, settings, pairs, solver, joint, 0, -1)
            if joint.impact_pair_event[p][0] >= 0.0:
                joint.impact_member_list[count] = p
                count += 1
    for sweep in range(1, IN_ORDER_SWEEPS):
        changed = int(0)
        for k in range(count):
            q = joint.impact_member_list[wp.where(sweep % 2 == 1, count - 1 - k, k)]
            if q < 0:
                changed += joint_terrain_body(-q - 1, model, settings, slots, solver, joint, sweep, sweep - 1)
            else:
                changed += joint_pair(q, model, settings, pairs, solver, joint, sweep, sweep - 1)
        if changed == 0:
            break  # every later sweep would skip every member (impact.unchanged_since)
    for k in range(count):
        q = joint.impact_member_list[k]
        if q < 0:
            bounce_terrain_body(-q - 1, model, settings, slots, solver, joint, IN_ORDER_SWEEPS)
        else:
            bounce_pair(q, model, settings, pairs, solver, joint, IN_ORDER_SWEEPS)
