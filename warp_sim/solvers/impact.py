"""Impacts: restitution and impact friction, resolved before the contact solve of a substep.

Why a stage of its own.  The soft solve (soft_step.py) holds loads and pushes bodies apart; its
accumulated impulse mixes the impact with the load it holds, the position bias and the warm
start.  Bouncing by a share of that impulse (the earlier design) bounced resting stacks under
heavy load, created spin where Gauss-Seidel spread the impulse unevenly over a face, and lost
energy where it had not converged.  So an impact is solved apart, on the velocities the last
substep's solve left (this substep's gravity not yet added), and only where a contact closes
faster than ``restitution_threshold``:

    v-  = v_in - (1 - alpha) g h     (the velocity at the end of the last solve; alpha: integrate.py)
    resting contacts approach at ~0, so they never bounce, whatever load they hold (g, mass ratio)

Model of one impact (one manifold: the terrain contacts of one body, or the points of one pair)
is Poisson's hypothesis, solved to convergence:

    compression: impulses P_c >= 0 with v_n(v_c) >= 0 at every engaged point and P_c . v_n = 0
                 (projected Gauss-Seidel on the manifold's points, swept until converged)
    restitution: P_r = e P_c at every point

For a frictionless manifold v_c is the M-metric projection of v- onto the non-approaching
velocities, unique even when P_c is not (four corners of a face), so the result v+ = (1 + e) v_c
- e v- is symmetric for a symmetric impact (no spin from a flat drop) and its kinetic energy is

    |v+|^2_M = (1 - e^2) |v_c|^2_M + e^2 |v-|^2_M  <=  |v-|^2_M      (equal for e = 1)

because v_c . M (v_c - v-) = P_c . J v_c = 0 at convergence.  Friction of the impact is Coulomb's
on the whole normal impulse: |P_t| <= mu (1 + e) P_c per point, against the slip left after the
normal impulses (a sphere hitting a plane at (3, -5) m/s with e = 0.5, mu = 0.1 leaves at
v_x = 3 - 0.1 * 1.5 * 5 = 2.25).

Manifolds closing together at the stage's start and sharing a body are first taken as one
impact (impact_joint.py).  Between manifolds the impacts then propagate in sequence:
IMPACT_SWEEPS rounds of IMPACT_INNER Gauss-Seidel sweeps over all manifolds, alternating
direction, each manifold re-tested on the current velocities.  A row of touching balls struck at one end is then a chain of two-body
impacts: with e = 1 the last ball leaves with the striker's velocity and the others stop
(Newton's cradle), momentum exactly and kinetic energy to rounding kept; two sweeps in opposite
directions carry a straight chain in either body order.

Which manifolds take part.  A manifold bounces (Poisson's e) when one of its engaged points closes
faster than ``restitution_threshold`` (default 0, so every impact the stage takes bounces); it
is still taken, inelastically (e = 0), when one closes faster than ``engage_speed`` (a substep
of gravity: resting contacts stay below it).  Without the second rule a blow passed down a pile
stopped at the first contact it reached below a 1 m/s threshold: a plate falling at 6.5 m/s on four plates left them all moving down at 0.3 to 1.1 m/s,
each contact closing under 1 m/s, and the soft solve then let them sink 6 to 9 mm into each other.
Gauss-Seidel carries such a chain slowly (a column pressed on the ground converges like a
diffusion, about N^2 sweeps for N bodies), so the stage runs 16 sweeps; each counts as a sweep
number, and a manifold neither of whose bodies an impact has changed since it was last taken is
skipped at once (``solver_impact_stamp``, ``unchanged_since``), so sweeps past the first cost
only where a blow is still travelling.  On the CPU slab schedule the IMPACT_INNER sweeps of a round
run inside one launch (domains.py); the colour schedule launches them one by one.  While the last
round still changed a body (``impacts_travelling``), two more rounds run, again and again, at most
plan.TRAVEL_LOOPS times (a device flag, ``wp.capture_while``: no host read, and nothing to pay in
a substep whose blows have settled).  Without them a light body between heavy ones, which takes
many blows back and forth, was stopped after the 16 sweeps: a 0.01 kg ball touching two 1 kg
ones, struck at 2 m/s with e = 1, lost 30 % of the kinetic energy, and rows of unequal masses
up to 6 %.  What a chain longer than all the sweeps leaves is stopped by the soft solve,
inelastically (energy can only be lost).

A contact whose gap is still open is engaged when it would close within the substep: when the
gap at its end, gap + h (v_n + h g.n) with the substep's kick, is under zero (without the kick, a
contact closed by the kick alone was left to the solve's speculative row, which met it
inelastically: a cube dropped with e = 0.8 from a band of heights g h^2 wide bounced 11 mm
short).  Its velocities change at the substep's start, but the bodies reach the contact only at
t* = gap / |v_n| (the earliest engaged point of the manifold; 0 when one is already touching;
for two spheres the exact root of |d + t v| = R_i + R_j, and for a sphere on a box refined on
the contact found again at t*).  Moving the whole substep with v+ would bounce it up to h |v_n|
early (a cube dropped flat from 2 m with e = 0.3 rose 13 mm too high), so each impact also
leaves each body the position shift t* (v- - v+) that the piecewise motion, v- until t* and v+
after, adds to h v+ (solver_toi_shift, spent by the next integration).  Along the normal the gap
at the substep's end is then e (h |v_n| - gap) >= 0: the body bounces from the surface, never
into it.  The impact itself acts on the velocity gravity has grown by t* (v- + g t*), and the
substep's kick adds only the g (h - t*) after it: a rebound taken at the start lost (1 + e) g t*
of its speed.  Gravity here is each body's share that its contacts do not hold (staged.
support_share, free_fall_share): a box resting on the ground gains nothing by t*, and counting
g t* for it too cancelled the striker's own from the closing speed.

The impulse acts where the bodies touch at t*: a pair's points are taken at the poses t* v and
t* w carry the bodies to (pair_geometry.pair_point_now), one point of both bodies, so the
impulse keeps linear and angular momentum about it, and the shifts carry that to the substep's
end.  Taken at the substep's start instead, two balls still up to h |v| apart met along the
wrong line (a billiard cut shot at 3 m/s sent the object ball 7.6 degrees off the line of
centres), and between moving bodies the shifts had to be dropped (the start's arms with t*'s
centres broke angular momentum by t* (v_i - v_j) x P), so a cube thrown at a free box rebounded
from up to h |v| before it touched (19 mm off the gap the piecewise motion gives).  A sequence of
events in one substep adds its shifts: a ball struck at t1 that meets a wall at t2 and comes back
to the striker at t3 ends where the three events put it, and the solve's speculative rows count
the shifts too (pair_solve.solve_pair_points).  Only the centre is shifted; the turn of an
off-centre impact still starts at the substep's start.

A body meets what lies nearest first: a terrain point closing after one of the body's pairs does
is ``shadowed`` until an impact has changed the body (pair_contact_times says why).  Between pairs
the sweep order decides: a body closing on two others within one substep takes them in pair order.
"""

import warp as wp

from ..kernel_args import BodyModel, BodyState, PairContacts, TerrainContacts
from ..integrate import pre_kick_fraction, world_inv_inertia
from ..types import ROTATION_MATRIX
from .impact_pair import (POINTS, compress_pair, pair_engagement, pair_impact_friction, pair_kick,
                          pair_manifold_at, restitute_pair)
from .impact_point import engage_speed, engaged, free_fall_share, spheres_miss, time_to_contact
from .impact_terrain import impact_terrain
from .pair_geometry import pair_point_now, read_pair_velocity
from .solver_args import JointImpacts, SolverBodies, StepSettings

wp.set_module_options({"enable_backward": False})

# Rounds of sweeps over all manifolds of a substep, and sweeps a round (alternating direction).
# 4 x 1 carry straight chains in either order; a plate struck onto a column of four needs more
# (module docstring): at 4 x 4 the deepest pair of the audit's plate rain fell from 28.9 to 22.9 mm
# (mean of 6 seeds); 64 sweeps would still gain (the column converges like a diffusion).
IMPACT_SWEEPS = 4
IMPACT_INNER = 4
# a body's last event partner (solver_event_partner): none yet in the substep, or something the
# pair test cannot name (the terrain, split overflow pairs)
NO_EVENT = -1
OTHER_EVENT = -2
# A manifold's part in the stage's simultaneous impact (impact_joint.py), as (t*, e): none, or
# closing at the stage's start (its t* and e found by the joint phase's first sweep)
NOT_MEMBER = wp.constant(wp.vec2(-1.0, 0.0))
CLOSING = wp.constant(wp.vec2(-2.0, 0.0))


@wp.func
def body_inv_inertia_world(rot: wp.mat33, body_d: wp.vec3, rotation: int) -> wp.mat33:
    """R I^-1 R^T, taken as exactly d 1 for an isotropic body (sphere, cube) unless the rotation is
    the raw matrix mode (its R drifts from orthonormal by design); staged.prepare_body says why."""
    if rotation != ROTATION_MATRIX and body_d[0] == body_d[1] and body_d[1] == body_d[2]:
        return wp.diag(body_d)
    return world_inv_inertia(rot, body_d)


@wp.func
def impact_begin_body(
    i: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    reset_reference: int,
    # State in
    state_in: BodyState,
    # Solver out
    solver: SolverBodies,
    joint_phase: int,
    joint: JointImpacts,
):
    """The velocities the impacts act on: those the last solve left, without this substep's
    gravity (prepare_body adds it back, and the contact solve then holds it as a load); with
    ``joint_phase``, kept as the start velocities too (impact_joint.py)."""
    solver.solver_toi_shift[i] = wp.vec3(0.0)
    solver.solver_impact_stamp[i] = -1
    solver.solver_pair_toi[i] = settings.h
    solver.solver_event_partner[i] = NO_EVENT
    if joint_phase != 0:
        joint.impact_member_count[i] = 0
    if reset_reference != 0:
        solver.solver_ref_pos[i] = state_in.body_pos[i]
        solver.solver_ref_rot[i] = state_in.body_rot[i]
        solver.solver_drift_p[i] = wp.vec3(0.0)
        solver.solver_drift_r[i] = wp.mat33(0.0)
    if model.body_inv_mass[i] == 0.0:
        solver.solver_v[i] = wp.vec3(0.0)
        solver.solver_w[i] = wp.vec3(0.0)
        if joint_phase != 0:
            joint.impact_v_start[i] = wp.vec3(0.0)
            joint.impact_w_start[i] = wp.vec3(0.0)
        solver.solver_inv_inertia[i] = wp.mat33(0.0)
        return
    inv_inertia = body_inv_inertia_world(state_in.body_rot[i], model.body_inv_inertia[i], settings.rotation)
    solver.solver_inv_inertia[i] = inv_inertia
    after_kick = (1.0 - pre_kick_fraction(settings.integrator)) * settings.h
    v = state_in.body_vel[i] - after_kick * settings.gravity
    w = inv_inertia * state_in.body_angmom[i]
    solver.solver_v[i] = v
    solver.solver_w[i] = w
    if joint_phase != 0:
        # kept through the stage: simultaneous impacts are told and placed on them (impact_joint.py)
        joint.impact_v_start[i] = v
        joint.impact_w_start[i] = w


@wp.func
def unchanged_since(stamp: int, since: int) -> bool:
    """A body whose velocity no impact has changed since sweep ``since`` (the sweep in which the
    manifold at hand was last taken; < 0 in a substep's first sweep, which takes every manifold)."""
    return since >= 0 and stamp < since


@wp.func
def shadowing_pair_time(i: int, settings: StepSettings, solver: SolverBodies) -> float:
    """The pair event that shadows body i's later terrain points (``shadowed``) while no impact has
    changed the body in this substep (the times are the stage's start's); after, h: none does."""
    return wp.where(solver.solver_impact_stamp[i] < 0, solver.solver_pair_toi[i], settings.h)


@wp.func
def impact_terrain_body(
    i: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
    impact_sweep: int,
    impact_since: int,
):
    inv_mass = model.body_inv_mass[i]
    e = model.body_restitution[i]
    if inv_mass == 0.0 or unchanged_since(solver.solver_impact_stamp[i], impact_since):
        return
    hit = impact_terrain(model.body_checkpoint_start[i], model.body_checkpoint_count[i], solver.solver_ref_pos[i],
                         solver.solver_v[i], solver.solver_w[i], inv_mass, solver.solver_inv_inertia[i],
                         solver.solver_drift_p[i], solver.solver_drift_r[i], e, model.body_friction[i], settings.h,
                         settings.gravity, settings.restitution_threshold, shadowing_pair_time(i, settings, solver), settings.soft[3],
                         slots.terrain_contact_active,
                         slots.terrain_contact_point, slots.terrain_contact_normal, slots.terrain_contact_depth,
                         solver.impact_normal, solver.impact_tangent)
    if hit.hit == 0:
        return
    solver.solver_w[i] = hit.w
    solver.solver_v[i] = hit.v
    solver.solver_toi_shift[i] = solver.solver_toi_shift[i] + hit.shift
    solver.solver_impact_stamp[i] = impact_sweep
    solver.solver_event_partner[i] = OTHER_EVENT


@wp.func
def pair_event_start(i: int, j: int, solver: SolverBodies) -> float:
    """When pair (i, j) struck earlier in the substep, if that was each dynamic body's last event
    (a static body keeps none); 0 otherwise.  impact_pair_velocity says why."""
    partner_j = solver.solver_event_partner[j]
    if solver.solver_event_partner[i] == j and (partner_j == i or partner_j == NO_EVENT):
        return solver.solver_event_time[i]
    if partner_j == i and solver.solver_event_partner[i] == NO_EVENT:
        return solver.solver_event_time[j]
    return 0.0


@wp.struct
class PairImpact:
    """A pair's impact: both bodies' new velocities (without the gravity of t*), each one's
    time-of-impact shift from this pair, and whether the pair struck (``hit``)."""

    vi: wp.vec3
    wi: wp.vec3
    vj: wp.vec3
    wj: wp.vec3
    shift_i: wp.vec3
    shift_j: wp.vec3
    hit: int
    toi: float
    clear: int  # pair_engagement's: a ball and a spinning box that pass clear


@wp.func(inline=True)
def impact_pair_velocity(
    p: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pairs: PairContacts,
    # Solver in
    solver: SolverBodies,
    vi: wp.vec3,
    wi: wp.vec3,
    vj: wp.vec3,
    wj: wp.vec3,
    inv_mi: float,
    inv_mj: float,
    inv_ii: wp.mat33,
    inv_ij: wp.mat33,
) -> PairImpact:
    """The impact of pair p from the velocities given, with the inverse masses given (the
    bodies' own, or split ones: pair_overflow.py); writes nothing."""
    out = PairImpact()
    out.hit = 0
    out.clear = 0
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    e = wp.max(model.body_restitution[i], model.body_restitution[j])
    count = pairs.pair_point_count[p]
    # the shifts of impacts taken earlier in the substep are motion the bodies make too (v- until
    # their t*): a box bounced off one corner late in the substep keeps closing on the rest
    dpi = solver.solver_drift_p[i] + solver.solver_toi_shift[i]
    dpj = solver.solver_drift_p[j] + solver.solver_toi_shift[j]
    # A pair whose impact was its bodies' last event is looked at from that impact, t0, on: the
    # start pose plus the shifts is where v+ would have carried the bodies from the substep's
    # start, which they never were, and there the gap of two balls along that pose's line of
    # centres had them overlapping and struck them again (a ball at 1.25 diameters a substep,
    # grazing another at 0.8 of a diameter, sent it 4 degrees off the line of centres).  Only
    # then: the sweeps take a body's pairs in pair order, not in time, and looked at from a later
    # event of one body with a third, this pair was struck past its own contact (64 balls on a
    # free plank gained 1e-6 of their energy a step).  Otherwise, and for two boxes, the start pose
    # plus the shifts, exact along a fixed normal whatever the order (a box pair's normal is its
    # pass's; looked at from t0 on, the plate rain's deepest layout went from 4.5 to 11.1 mm).
    t0 = float(0.0)
    if model.body_sphere_radius[i] > 0.0 or model.body_sphere_radius[j] > 0.0:
        t0 = pair_event_start(i, j, solver)
    engagement = pair_engagement(p, model, settings, pairs, solver, vi, wi, vj, wj, inv_mi, inv_mj, dpi, dpj, t0)
    out.clear = engagement.clear
    if engagement.hit == 0:
        return out
    if engagement.bounces == 0:
        e = 0.0
    toi = engagement.toi
    # the impulse acts where the bodies touch, at t*: the points' geometry there, the bodies moved
    # on by t* v and turned by t* w.  Taken at the substep's start instead, two balls still up to
    # h |v| apart met along the wrong line (a billiard cut shot at 3 m/s sent the object ball 7.6
    # degrees off the line of centres) and a ball rolling into a step's edge was pushed along the
    # edge-to-centre line of before it touched (14 % of its speed lost, e = 0, mu = 0).  Every
    # body's centre is then shifted to the piecewise motion (v- until t*, v+ after), moving bodies
    # too: the impulse, at one point of both at t*, keeps linear and angular momentum about that
    # point (pair_geometry.py), and the shifts carry that to the end of the substep:
    # L = sum x(t*) x m v+ + spins, as the piecewise motion has it.
    m = pair_manifold_at(p, toi, model, pairs, solver, vi, wi, vj, wj, dpi, dpj, engagement.acc)
    # the impact acts at t*, on the velocities gravity has grown by then: a resting body's contacts
    # hold it (staged.support_share), a falling one has gained g t*
    gi = (free_fall_share(inv_mi, solver.solver_support[i]) * toi) * settings.gravity
    gj = (free_fall_share(inv_mj, solver.solver_support[j]) * toi) * settings.gravity
    m.vi = vi + gi
    m.wi = wi
    m.vj = vj + gj
    m.wj = wj
    vi_in = m.vi
    vj_in = m.vj
    m = compress_pair(m, count, inv_mi, inv_mj, inv_ii, inv_ij)
    m = restitute_pair(m, count, e, inv_mi, inv_mj, inv_ii, inv_ij)
    mu = wp.sqrt(model.body_friction[i] * model.body_friction[j])
    if mu > 0.0:
        m = pair_impact_friction(m, count, e, mu, inv_mi, inv_mj, inv_ii, inv_ij)
    out.hit = 1
    out.toi = toi
    out.vi = m.vi - gi
    out.wi = m.wi
    out.vj = m.vj - gj
    out.wj = m.wj
    out.shift_i = toi * (vi_in - m.vi)
    out.shift_j = toi * (vj_in - m.vj)
    return out


@wp.func(inline=True)
def impact_pair(
    p: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    impact_sweep: int,
    impact_since: int,
):
    """The impact of pair p (its manifold's points, at the current pose: pair_geometry.py; the
    algebra of pair_solve.py, impulse +P on i)."""
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    if pairs.pair_point_count[p] == 0:
        return
    stamps = solver.solver_impact_stamp
    if unchanged_since(stamps[i], impact_since) and unchanged_since(stamps[j], impact_since):
        return
    inv_mi = model.body_inv_mass[i]
    inv_mj = model.body_inv_mass[j]
    if inv_mi == 0.0 and inv_mj == 0.0:
        return
    out = impact_pair_velocity(p, model, settings, pairs, solver, solver.solver_v[i], solver.solver_w[i],
                               solver.solver_v[j], solver.solver_w[j], inv_mi, inv_mj, solver.solver_inv_inertia[i],
                               solver.solver_inv_inertia[j])
    pairs.pair_passes_clear[p] = out.clear
    if out.hit == 0:
        return
    # only dynamic bodies are written: a static body may sit in many pairs of one colour
    if inv_mi > 0.0:
        solver.solver_impact_stamp[i] = impact_sweep
        solver.solver_event_time[i] = out.toi
        solver.solver_event_partner[i] = j
        solver.solver_v[i] = out.vi
        solver.solver_w[i] = out.wi
        solver.solver_toi_shift[i] = solver.solver_toi_shift[i] + out.shift_i
    if inv_mj > 0.0:
        solver.solver_impact_stamp[j] = impact_sweep
        solver.solver_event_time[j] = out.toi
        solver.solver_event_partner[j] = i
        solver.solver_v[j] = out.vj
        solver.solver_w[j] = out.wj
        solver.solver_toi_shift[j] = solver.solver_toi_shift[j] + out.shift_j


@wp.kernel
def impact_begin(
    tid_offset: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    reset_reference: int,
    # State in
    state_in: BodyState,
    # Solver out
    solver: SolverBodies,
    joint_phase: int,
    joint: JointImpacts,
):
    # a twin of impact_begin_body (domain_sweep calls it too): the colour schedule launches it per body
    impact_begin_body(wp.tid() + tid_offset, model, settings, reset_reference, state_in, solver, joint_phase, joint)


@wp.kernel
def terrain_impact(
    tid_offset: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
    # In
    impact_sweep: int,
    impact_since: int,
):
    # a twin of impact_terrain_body (domain_sweep calls it too): the colour schedule launches it per body
    impact_terrain_body(wp.tid() + tid_offset, model, settings, slots, solver, impact_sweep, impact_since)


@wp.kernel
def pair_contact_times(
    tid_offset: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in
    pair_count: wp.array(dtype=wp.int32),
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    joint_phase: int,
    joint: JointImpacts,
):
    """Each body's earliest pair event of the substep (solver_pair_toi, reset to h by the impact
    begin): when a point of one of its pairs, closing faster than the engage speed, touches.

    A plate falling on a plate that lies on the ground has speculative contacts with both, and once
    the lower plate is thinner than a substep's fall (h |v_n|) the ground's close within the
    substep too, through it.  A sweep takes the terrain before the pairs, so the ground's impact
    bounced the upper plate with the ground's time of impact (3 ms into a 4 ms substep instead of
    0.35 ms), the pair then saw it separating, and it ended 18 mm deep in a 20 mm plate.  So a
    terrain point that would close after the body's earliest pair event waits (``shadowed``) until
    an impact has changed the body; the later sweeps take it on the new velocities, so a body
    knocked onto the ground within the substep still bounces there.  Run before the impact sweeps
    (again after a pass that found new pairs); atomic_min: the same whatever the thread order."""
    p = wp.tid() + tid_offset
    if p >= pair_count[0]:
        return
    pairs.pair_passes_clear[p] = 0  # until this substep's impact stage finds otherwise
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    vel = read_pair_velocity(solver, i, j)
    toi = settings.h
    kick = pair_kick(i, j, model.body_inv_mass[i], model.body_inv_mass[j], settings, solver)
    for k in range(pairs.pair_point_count[p]):
        now = pair_point_now(pairs.pair_normal[p], pairs.pair_point[p * POINTS + k], pairs.pair_depth[p * POINTS + k],
                             pairs.pair_feature[p * POINTS + k], solver.solver_ref_pos[i], solver.solver_ref_pos[j],
                             solver.solver_drift_p[i], solver.solver_drift_p[j], solver.solver_drift_r[i],
                             solver.solver_drift_r[j], solver.solver_ref_rot, i, j, model)
        vn = wp.dot(vel.vi + wp.cross(vel.wi, now.arm_i) - vel.vj - wp.cross(vel.wj, now.arm_j), now.normal)
        if (engaged(now.separation, vn + wp.dot(kick, now.normal), settings.h)
                and vn < -engage_speed(settings.gravity, settings.h)):
            toi = time_to_contact(now.separation, vn, toi)
    radius_i = model.body_sphere_radius[i]
    radius_j = model.body_sphere_radius[j]
    if toi < settings.h and radius_i > 0.0 and radius_j > 0.0:
        d = (solver.solver_ref_pos[i] + solver.solver_drift_p[i]) - (solver.solver_ref_pos[j] + solver.solver_drift_p[j])
        if spheres_miss(d, vel.vi - vel.vj, radius_i + radius_j, settings.h, settings.h * wp.length(kick)):
            toi = settings.h
    if toi < settings.h:
        wp.atomic_min(solver.solver_pair_toi, i, toi)
        wp.atomic_min(solver.solver_pair_toi, j, toi)
        # a member of the stage's simultaneous impact where its gap is still open (impact_joint.py
        # says why), counted on its dynamic bodies (a static body couples nothing); the count is an
        # integer sum, the same in any thread order
        if joint_phase != 0 and toi > 0.0:
            joint.impact_pair_event[p] = CLOSING
            if model.body_inv_mass[i] > 0.0:
                wp.atomic_add(joint.impact_member_count, i, 1)
            if model.body_inv_mass[j] > 0.0:
                wp.atomic_add(joint.impact_member_count, j, 1)
        elif joint_phase != 0:
            joint.impact_pair_event[p] = NOT_MEMBER
    elif joint_phase != 0:
        joint.impact_pair_event[p] = NOT_MEMBER


@wp.kernel
def impacts_travelling(
    tid_offset: int,
    first_sweep: int,
    last_sweep: int,
    # Solver in
    solver_impact_stamp: wp.array(dtype=wp.int32),
    # Out
    travelling: wp.array(dtype=wp.int32),
):
    """Whether an impact sweep numbered first_sweep to last_sweep changed any body (its stamp):
    then a blow is still travelling.  A maximum by atomics, the same whatever the threads' order."""
    i = wp.tid() + tid_offset
    stamp = solver_impact_stamp[i]
    if stamp >= first_sweep and stamp <= last_sweep:
        wp.atomic_max(travelling, 0, 1)


@wp.kernel
def count_travel_loop(
    max_loops: int,
    # Solver in/out
    travel_loops: wp.array(dtype=wp.int32),
    # Out
    travelling: wp.array(dtype=wp.int32),
):
    """One thread: counts the loop's passes and ends it at ``max_loops``."""
    travel_loops[0] = travel_loops[0] + 1
    if travel_loops[0] >= max_loops:
        travelling[0] = 0
