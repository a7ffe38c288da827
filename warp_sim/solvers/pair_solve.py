"""Pair stages of the staged soft-step solver: one thread per pair of one colour.

See staged.py for the algebra.  A launch handles one colour; its pair range is read on the
device from ``color_start`` (so the launch sequence can be captured in a CUDA graph).  The
overflow colour's pairs may share bodies: on CUDA pair_overflow.py sweeps them with split masses
(their chain passes are walked in order by one thread), on the CPU one thread walks them.
"""

import warp as wp

from ..collide.contact_patch import NO_TWIST, twist_arm
from ..kernel_args import BodyModel, BodyState, PairContacts, TerrainContacts
from ..schedule.coloring import color_range
from .impact import impact_pair, pair_event_start
from .impact_joint import IMPACT_BOUNCE, IMPACT_JOINT, IMPACT_SEQUENTIAL
from .impact_point import engage_speed, spheres_miss
from .contact_rows import closed_contact_bias, closed_during_substep, loaded_soft
from .pair_geometry import PairVelocity, pair_point_now, read_pair_velocity
from .rolling import hold_ball_on_static, static_ball_side
from .solver_args import SolverBodies, StepSettings
from .staged import sweep_body_terrain

wp.set_module_options({"enable_backward": False})

POINTS = 4

MODE_WARM_START = 0
MODE_SOLVE = 1
MODE_RELAX = 2
MODE_IMPACT = IMPACT_SEQUENTIAL  # impact.py: restitution and impact friction, before the warm start
# impact_joint.py: the impacts closing at the stage's start, compressed together, then bounced
MODE_IMPACT_JOINT = IMPACT_JOINT
MODE_IMPACT_BOUNCE = IMPACT_BOUNCE
# relax of a scene with restitution: open gaps are left to the next substep's impact stage, which
# bounces them with their full approach speed (a relax impulse would take part of it away)
MODE_RELAX_CLOSED = 4
RELAX_MODES = (MODE_RELAX, MODE_RELAX_CLOSED)

# A light body pressed onto its terrain contacts by a much heavier one: plain Gauss-Seidel hands the
# heavy body's load down through the light one by about m / M of it a sweep (the light body is
# pushed down by the pair, then stopped by the ground, then pushed again), so 1e4 kg on 1 kg needed
# some 20 sweeps to settle.  After its solve sweep, a pair whose masses differ by CHAIN_MASS_RATIO
# or more walks the lighter body's terrain contacts and the pair's points again (chain_pair), up to
# CHAIN_PASSES - 1 times, until a pass moves neither by more than convergence_tolerance: the same
# equations, solved further where the mass ratio makes one sweep do little.  The pair's thread owns
# both bodies in its launch (a colour or a slab), so the lighter body's terrain slots are written by
# no other thread.
CHAIN_MASS_RATIO = 10.0
CHAIN_PASSES = 16
# A relax that lets go of a push worth this many convergence tolerances walks on to the ground
# (relax_chain_needed).  What it leaves behind without the walk is the share of the push that its
# partner's terrain rows stop, at most half of it for a partner as heavy as the pushed body or
# heavier, so walking the pairs that let go of 20 tolerances or more keeps every push-out under
# the 10 tolerances of Gauss-Seidel's own error (tests/test_push_out.py).  In the 10k rain 1.5 %
# of the pairs walk at the last relax of a step (2.3 % at 10 tolerances).
RELAX_CHAIN_TOLERANCES = 20.0


@wp.func
def heavy_partner_mass(inv_mass: float, other_inv_mass: float) -> float:
    """The other body's mass when this one is CHAIN_MASS_RATIO or more times lighter (both
    dynamic), else 0: the load the heavy-on-light damping and chain passes are for."""
    if other_inv_mass > 0.0 and inv_mass >= CHAIN_MASS_RATIO * other_inv_mass:
        return 1.0 / other_inv_mass
    return 0.0


@wp.func
def apply_pair_impulse(vel: PairVelocity, impulse: wp.vec3, ri: wp.vec3, rj: wp.vec3, inv_mi: float, inv_mj: float,
                       inv_ii: wp.mat33, inv_ij: wp.mat33) -> PairVelocity:
    out = vel
    out.vi = vel.vi + inv_mi * impulse
    out.wi = vel.wi + inv_ii * wp.cross(ri, impulse)
    out.vj = vel.vj - inv_mj * impulse
    out.wj = vel.wj - inv_ij * wp.cross(rj, impulse)
    return out


@wp.func
def pair_change(before: PairVelocity, after: PairVelocity, reach_i: float, reach_j: float) -> float:
    """How far a pass moved the pair's bodies: the largest speed change of a point of either body,
    bounded by |dv| + reach |dw| (the passes stop below convergence_tolerance)."""
    return (wp.length(after.vi - before.vi) + wp.length(after.vj - before.vj)
            + reach_i * wp.length(after.wi - before.wi) + reach_j * wp.length(after.wj - before.wj))


@wp.func
def relative_velocity(vel: PairVelocity, ri: wp.vec3, rj: wp.vec3) -> wp.vec3:
    return vel.vi + wp.cross(vel.wi, ri) - vel.vj - wp.cross(vel.wj, rj)


@wp.func
def normal_mass_inverse(n: wp.vec3, ri: wp.vec3, rj: wp.vec3, inv_mi: float, inv_mj: float, inv_ii: wp.mat33,
                        inv_ij: wp.mat33) -> float:
    rni = wp.cross(ri, n)
    rnj = wp.cross(rj, n)
    return inv_mi + inv_mj + wp.dot(rni, inv_ii * rni) + wp.dot(rnj, inv_ij * rnj)


@wp.func
def reset_rolling(p: int, pairs: PairContacts):
    """A warm start's reset of a sphere pair's rolling-resistance accumulator (its second slot, as
    its one point leaves that slot free): it starts each substep at zero.  Kept from substep to
    substep it stays at its clamp, and a ball on a dynamic floor, warm-started across two slabs,
    had its resistance once a step (1 / substeps of it)."""
    if pairs.pair_point_count[p] == 1:
        pairs.pair_tangent_impulse[p * POINTS + 1] = wp.vec3(0.0)


@wp.func(inline=True)
def solve_pair_points(
    p: int,
    mode: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in/out
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    vel_in: PairVelocity,
    inv_mi: float,
    inv_mj: float,
    inv_ii: wp.mat33,
    inv_ij: wp.mat33,
) -> PairVelocity:
    """Pair p's points swept once (``mode``: warm start, solve or relax) from the velocities
    ``vel_in``, with the inverse masses given; returns the new velocities and writes only the
    pair's own impulses (and a load mass, by maximum).  solve_one_pair gives it the bodies' own
    masses and writes the result back; pair_overflow.py gives split masses to pairs that share
    bodies within one launch and sums the results."""
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    xi = solver.solver_ref_pos[i]
    xj = solver.solver_ref_pos[j]
    drift_pi = solver.solver_drift_p[i]
    drift_pj = solver.solver_drift_p[j]
    drift_ri = solver.solver_drift_r[i]
    drift_rj = solver.solver_drift_r[j]
    vel = vel_in
    friction = wp.sqrt(model.body_friction[i] * model.body_friction[j])
    count = pairs.pair_point_count[p]
    # rolling resistance of a sphere in the pair (terrain contacts: rolling.solve_rolling); a
    # sphere's pair has one point, so the pair's second slot keeps its accumulated angular impulse
    rolling_arm = wp.max(model.body_rolling_arm[i], model.body_rolling_arm[j])
    # a ball on a static body is held still at once where it can be (rolling.hold_ball_on_static)
    ball_side = int(0)
    if count == 1:
        ball_side = static_ball_side(model.body_rolling_arm[i], model.body_rolling_arm[j], model.body_inv_mass[i],
                                     model.body_inv_mass[j])
    held = int(0)
    if mode == MODE_WARM_START:
        reset_rolling(p, pairs)

    # a relax walks the pair's own points again until a pass moves nothing (staged.sweep_body_terrain
    # says why: one pass gives back only part of the push-out speed); so does a solve sweep whose
    # first pass took a blow (below)
    passes = wp.where(mode != MODE_WARM_START and count > 1, settings.relax_passes, 1)
    blow = int(0)
    reach_i = wp.length(model.body_size[i])
    reach_j = wp.length(model.body_size[j])
    # the heavier body's mass where the pair's masses differ by CHAIN_MASS_RATIO or more (with
    # gravity, contact_rows.loaded_soft damps the contact for it; from about 12 on it changes it),
    # from the bodies' own masses (a split pair, pair_overflow.py, solves with scaled ones)
    own_inv_mi = model.body_inv_mass[i]
    own_inv_mj = model.body_inv_mass[j]
    heavy_mass = wp.max(heavy_partner_mass(own_inv_mi, own_inv_mj), heavy_partner_mass(own_inv_mj, own_inv_mi))
    if heavy_mass > 0.0 and mode == MODE_WARM_START:
        # the lighter body's terrain contacts carry the heavy one too (staged.sweep_body_terrain);
        # a maximum, so split pairs sharing the light body may write it in any order
        light_body = wp.where(own_inv_mi > own_inv_mj, i, j)
        wp.atomic_max(solver.solver_load_mass, light_body, heavy_mass)
    spheres_apart = model.body_sphere_radius[i] > 0.0 and model.body_sphere_radius[j] > 0.0
    reach = model.body_sphere_radius[i] + model.body_sphere_radius[j]
    # two balls whose last impact of the substep was with each other are looked at from it, t0, on
    # (impact.impact_pair_velocity says why): the start pose plus the shifts is where they never
    # were, and its line of centres, far from the one at t0 for a grazing hit, pushed them again
    # (a ball at 0.75 diameters a substep grazing another at 0.95 of a diameter: 0.13 of its speed
    # sideways instead of 0.10)
    # (a ball on a box keeps the start pose plus the shifts here: a face's normal is fixed, and an
    # edge's contact is found again wherever it lies; t0 = h, an impact at the substep's end,
    # leaves nothing to look at)
    # A ball and a box whose impact this substep was each one's last event were met by the impact
    # stage where they touch, at t*, the box turned by w t* (impact_pair.pair_manifold_at), and parted
    # there.  Their row is built at the start pose, turned by nothing, and for a box spinning fast
    # its normal is off the one at t* by up to |w| h: the point that parts along the one may still
    # close along the other, and the row stopped it, an inelastic blow after an elastic one (a box at
    # 40 rad/s grazing a ball with e = 1: 0.6 to 8 % of the pair's energy lost).
    t0 = float(0.0)
    bounced_apart = int(0)
    if mode == MODE_SOLVE and (model.body_sphere_radius[i] > 0.0 or model.body_sphere_radius[j] > 0.0):
        event = pair_event_start(i, j, solver)
        if spheres_apart:
            t0 = wp.where(event >= settings.h, 0.0, event)
        elif event > 0.0:
            bounced_apart = 1
    # friction acts at the arms of the pair's patch (collide/contact_patch.py: measured when its
    # points were found)
    twist = NO_TWIST
    if count > 1:
        twist = pairs.pair_twist[p]
    for _pass in range(passes):
        before = vel
        normal_total = float(0.0)
        for k in range(count):
            slot = p * POINTS + k
            # normal, arms and gap now (pair_geometry.py: one point for both bodies keeps angular momentum)
            # (where the point sits follows the bodies' own masses, split or not)
            at_pi = drift_pi
            at_pj = drift_pj
            if t0 > 0.0:
                at_pi = drift_pi + solver.solver_toi_shift[i] + t0 * vel.vi
                at_pj = drift_pj + solver.solver_toi_shift[j] + t0 * vel.vj
            now = pair_point_now(pairs.pair_normal[p], pairs.pair_point[slot], pairs.pair_depth[slot],
                                 pairs.pair_feature[slot], xi, xj, at_pi, at_pj, drift_ri, drift_rj,
                                 solver.solver_ref_rot, i, j, model)
            n = now.normal
            ri = now.arm_i
            rj = now.arm_j
            acc = pairs.pair_normal_impulse[slot]
            if mode == MODE_WARM_START:
                if twist[3] >= 1.0:
                    vel = apply_pair_impulse(vel, acc * n + pairs.pair_tangent_impulse[slot], ri, rj, inv_mi, inv_mj,
                                             inv_ii, inv_ij)
                else:
                    # friction at the patch's arms (collide/contact_patch.py): one point of both bodies,
                    # moved in the plane
                    tangent = pairs.pair_tangent_impulse[slot]
                    shift = twist_arm(ri, pairs.pair_point[slot], n, twist) - ri
                    impulse = acc * n + tangent
                    vel.vi = vel.vi + inv_mi * impulse
                    vel.wi = vel.wi + inv_ii * (wp.cross(ri, impulse) + wp.cross(shift, tangent))
                    vel.vj = vel.vj - inv_mj * impulse
                    vel.wj = vel.wj - inv_ij * (wp.cross(rj, impulse) + wp.cross(shift, tangent))
            else:
                separation = now.separation
                # Non-penetration
                k_n = float(0.0)
                bias = float(0.0)
                mass_scale = float(1.0)
                impulse_scale = float(0.0)
                vn = wp.dot(relative_velocity(vel, ri, rj), n)
                if mode == MODE_RELAX_CLOSED and closed_during_substep(separation, vn, settings.h):
                    continue
                if separation > 0.0:
                    # before the integration (the solve) the bodies' time-of-impact shifts are motion
                    # the substep makes too (impact.py): a ball struck late in a substep starts
                    # towards a wall only at t*, and the gap from its start pose let it close at
                    # gap / h only (a ball struck at 40 m/s left at 31 m/s)
                    shift = wp.vec3(0.0)
                    if mode == MODE_SOLVE and t0 == 0.0:
                        shift = solver.solver_toi_shift[i] - solver.solver_toi_shift[j]
                        separation = wp.max(separation + wp.dot(shift, n), 0.0)
                    left = settings.h - t0
                    bias = separation / left
                    if spheres_apart and spheres_miss((xi + at_pi) - (xj + at_pj) + shift, vel.vi - vel.vj, reach,
                                                      left, 0.0):
                        # two balls whose paths pass clear of each other in this substep: the gap
                        # along the line of centres closes, the balls do not (impact_point.spheres_miss);
                        # the row lets go of what it holds and pushes nothing
                        bias = wp.max(bias, -vn)
                    elif mode == MODE_SOLVE and bounced_apart != 0:
                        # a ball and a box that struck each other earlier in this substep, apart at the
                        # start pose: the impact stage met them where they touch, at t*, and they part
                        # there (see bounced_apart above): the row lets go too
                        bias = wp.max(bias, -vn)
                    elif mode == MODE_SOLVE and pairs.pair_passes_clear[p] != 0:
                        # a ball and a spinning box that the substep's impact stage found passing
                        # clear in free motion (pair_geometry.sphere_box_passes_clear; the test lives
                        # there, out of the sweeps, whose every row it slowed): the row lets go too
                        bias = wp.max(bias, -vn)
                elif mode == MODE_SOLVE:
                    soft = settings.soft
                    if heavy_mass > 0.0:
                        k_n = normal_mass_inverse(n, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
                        soft = loaded_soft(heavy_mass, 1.0 / k_n, settings.soft, settings.soft_load)
                    bias = closed_contact_bias(separation, settings.h, soft, settings.max_push_velocity)
                    mass_scale = soft[1]
                    impulse_scale = soft[2]
                old_t = pairs.pair_tangent_impulse[slot]
                if acc == 0.0 and vn + bias >= 0.0 and old_t[0] == 0.0 and old_t[1] == 0.0 and old_t[2] == 0.0:
                    # idle and staying idle: no normal impulse, so a Coulomb disc of radius 0 and no
                    # old friction to remove; the point would change nothing (contact_rows.py)
                    continue
                if k_n == 0.0:
                    k_n = normal_mass_inverse(n, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
                lam = -(mass_scale / k_n) * (vn + bias) - impulse_scale * acc
                new_acc = wp.max(acc + lam, 0.0)
                pairs.pair_normal_impulse[slot] = new_acc
                vel = apply_pair_impulse(vel, (new_acc - acc) * n, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij)
                # Friction: accumulated tangential impulse clamped to the Coulomb disc, at the patch's
                # arms (collide/contact_patch.py): one point of both bodies, moved in the plane
                ri_t = twist_arm(ri, pairs.pair_point[slot], n, twist)
                rj_t = rj + (ri_t - ri)
                vr = relative_velocity(vel, ri_t, rj_t)
                vt = vr - wp.dot(vr, n) * n
                old_t = old_t - wp.dot(old_t, n) * n
                new_t = old_t
                slip = wp.length(vt)
                if slip > 1.0e-9:
                    tangent = vt / slip
                    k_t = normal_mass_inverse(tangent, ri_t, rj_t, inv_mi, inv_mj, inv_ii, inv_ij)
                    new_t = old_t - (slip / k_t) * tangent
                limit = friction * new_acc
                mag = wp.length(new_t)
                if mag > limit:
                    new_t = new_t * (limit / mag)
                pairs.pair_tangent_impulse[slot] = new_t
                vel = apply_pair_impulse(vel, new_t - old_t, ri_t, rj_t, inv_mi, inv_mj, inv_ii, inv_ij)
                normal_total = normal_total + new_acc
                if ball_side != 0 and mode == MODE_SOLVE:
                    hold = hold_ball_on_static(vel, ball_side, n, ri, rj, inv_mi, inv_mj, inv_ii, inv_ij, friction,
                                               rolling_arm, new_acc, new_t, pairs.pair_tangent_impulse[p * POINTS + 1])
                    vel = hold.vel
                    held = hold.held
                    pairs.pair_tangent_impulse[slot] = hold.tangent_impulse
                    pairs.pair_tangent_impulse[p * POINTS + 1] = hold.rolling_impulse
        change = pair_change(before, vel, reach_i, reach_j)
        if change < settings.convergence_tolerance:
            break
        if mode == MODE_SOLVE:
            # A pass that moved a body by more than a substep of gravity (impact_point.engage_speed,
            # the most a pair holding a load changes by) met a blow, which two Gauss-Seidel sweeps
            # share unevenly between a face's points: a cube (e = 0) landing flat on a static box
            # left spinning at 0.12 rad/s.  Such a pair sweeps on until converged, as a body's cold
            # terrain rows do (soft_step.solve_sweeps); a pair holding a load keeps one pass.
            if _pass == 0 and change > engage_speed(settings.gravity, settings.h):
                blow = 1
            if blow == 0:
                break

    if rolling_arm > 0.0 and count == 1 and held == 0 and (mode == MODE_SOLVE or mode == MODE_RELAX or mode == MODE_RELAX_CLOSED):
        # against the relative spin, with the mass of its axis, clamped to c_r r J_n
        acc_roll = pairs.pair_tangent_impulse[p * POINTS + 1]
        spin = vel.wi - vel.wj
        speed2 = wp.dot(spin, spin)
        new_roll = acc_roll
        if speed2 > 1.0e-18:
            new_roll = acc_roll - (speed2 / (wp.dot(spin, inv_ii * spin) + wp.dot(spin, inv_ij * spin))) * spin
        limit = rolling_arm * normal_total
        mag2 = wp.dot(new_roll, new_roll)
        if mag2 > limit * limit:
            new_roll = new_roll * (limit / wp.sqrt(mag2))
        pairs.pair_tangent_impulse[p * POINTS + 1] = new_roll
        vel.wi = vel.wi + inv_ii * (new_roll - acc_roll)
        vel.wj = vel.wj - inv_ij * (new_roll - acc_roll)

    return vel


@wp.func(inline=True)
def solve_one_pair(
    p: int,
    mode: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in/out
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
    impact_sweep: int,
    impact_since: int,
):
    if mode == MODE_IMPACT:
        impact_pair(p, model, settings, pairs, solver, impact_sweep, impact_since)
        return
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    inv_mi = model.body_inv_mass[i]
    inv_mj = model.body_inv_mass[j]
    vel = solve_pair_points(p, mode, model, settings, pairs, solver, read_pair_velocity(solver, i, j), inv_mi, inv_mj,
                            solver.solver_inv_inertia[i], solver.solver_inv_inertia[j])
    # Only dynamic bodies are written: a static body may sit in many pairs of one colour.
    if inv_mi > 0.0:
        solver.solver_v[i] = vel.vi
        solver.solver_w[i] = vel.wi
    if inv_mj > 0.0:
        solver.solver_v[j] = vel.vj
        solver.solver_w[j] = vel.wj


@wp.func
def warm_start_pair_side(
    p: int,
    side: int,
    reset_reference: int,
    # Model
    model: BodyModel,
    # State in
    state_in: BodyState,
    # Contacts in/out
    pairs: PairContacts,
    # Solver in/out
    solver: SolverBodies,
):
    """Pair p's stored impulses applied to one of its bodies (side 0: body i gets +P; side 1: body j
    gets -P).  A warm start touches each body with its own arm and inverse mass only, so the two
    halves of a pair whose bodies belong to two threads can be applied by those two threads
    (solvers/domains.py) and sum to MODE_WARM_START of solve_one_pair.  The other body's reference
    pose is being reset by its own thread when ``reset_reference`` is set: it is then read from
    body_pos (drift zero), as that thread will write it."""
    if side == 0:
        # one side's thread only (reset_rolling says why it must happen here too)
        reset_rolling(p, pairs)
    ij = pairs.pair_body[p]
    b = ij[side]
    inv_mass = model.body_inv_mass[b]
    if inv_mass == 0.0:
        return
    i = ij[0]
    j = ij[1]
    carried = heavy_partner_mass(inv_mass, model.body_inv_mass[ij[1 - side]])
    if carried > 0.0:
        # as solve_one_pair's warm start: this lighter body carries the other one
        solver.solver_load_mass[b] = wp.max(solver.solver_load_mass[b], carried)
    sign = wp.where(side == 0, 1.0, -1.0)
    inv_inertia = solver.solver_inv_inertia[b]
    v = solver.solver_v[b]
    w = solver.solver_w[b]
    x_i = state_in.body_pos[i]
    x_j = state_in.body_pos[j]
    drift_pi = wp.vec3(0.0)
    drift_pj = wp.vec3(0.0)
    drift_ri = wp.mat33(0.0)
    drift_rj = wp.mat33(0.0)
    if reset_reference == 0:
        x_i = solver.solver_ref_pos[i]
        x_j = solver.solver_ref_pos[j]
        drift_pi = solver.solver_drift_p[i]
        drift_pj = solver.solver_drift_p[j]
        drift_ri = solver.solver_drift_r[i]
        drift_rj = solver.solver_drift_r[j]
    # the rotations the anchors turn from: the step's start where the pose is being reset
    rot_ref = solver.solver_ref_rot
    if reset_reference != 0:
        rot_ref = state_in.body_rot
    count = pairs.pair_point_count[p]
    # as solve_pair_points' warm start: friction at the arms of the pair's patch (contact_patch.py)
    twist = NO_TWIST
    if count > 1:
        twist = pairs.pair_twist[p]
    for k in range(count):
        slot = p * POINTS + k
        now = pair_point_now(pairs.pair_normal[p], pairs.pair_point[slot], pairs.pair_depth[slot],
                             pairs.pair_feature[slot], x_i, x_j, drift_pi, drift_pj, drift_ri, drift_rj, rot_ref, i, j,
                             model)
        arm = wp.where(side == 0, now.arm_i, now.arm_j)
        if twist[3] >= 1.0:
            impulse = sign * (pairs.pair_normal_impulse[slot] * now.normal + pairs.pair_tangent_impulse[slot])
            v = v + inv_mass * impulse
            w = w + inv_inertia * wp.cross(arm, impulse)
        else:
            tangent_part = sign * pairs.pair_tangent_impulse[slot]
            impulse = sign * pairs.pair_normal_impulse[slot] * now.normal + tangent_part
            shift = twist_arm(arm, pairs.pair_point[slot], now.normal, twist) - arm
            v = v + inv_mass * impulse
            w = w + inv_inertia * (wp.cross(arm, impulse) + wp.cross(shift, tangent_part))
    solver.solver_v[b] = v
    solver.solver_w[b] = w


# The modes a sweep kernel is compiled for, one kernel each (this module's PAIR_PASS and the slab
# schedule's domains.DOMAIN_SWEEP), by the name that ends the kernel's: with the mode a
# compile-time constant the other modes' branches fold away (domains.py says what that bought).
SWEEP_MODE_NAMES = {MODE_WARM_START: "warm_start", MODE_SOLVE: "solve", MODE_RELAX: "relax",
                    MODE_RELAX_CLOSED: "relax_closed", MODE_IMPACT: "impact"}


def pair_pass_for(mode: int):
    """The colour sweep of pair_solve mode ``mode`` (one of SWEEP_MODE_NAMES)."""

    @wp.kernel(name="pair_pass_" + SWEEP_MODE_NAMES[mode])
    def pair_pass(
        tid_offset: int,
        impact_sweep: int,
        impact_since: int,
        color: int,
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
    ):
        r = color_range(color, color_start, wp.tid() + tid_offset)
        for index in range(r[0], r[1]):
            p = color_pairs_sorted[index]
            if mode == MODE_RELAX or mode == MODE_RELAX_CLOSED:
                held = pair_normal_total(p, pairs)
                solve_one_pair(p, mode, model, settings, pairs, solver, impact_sweep, impact_since)
                pairs.pair_relax_chain[p] = relax_chain_needed(p, held, model, settings, pairs, solver)
            else:
                solve_one_pair(p, mode, model, settings, pairs, solver, impact_sweep, impact_since)

    return pair_pass


@wp.func
def chain_pair(
    p: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in/out
    pairs: PairContacts,
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
):
    """After pair p's solve sweep: where its masses differ by CHAIN_MASS_RATIO or more, walk the
    lighter body's terrain contacts and the pair's points again, up to CHAIN_PASSES - 1 times,
    until a pass moves neither body by more than convergence_tolerance (module comment)."""
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    inv_mi = model.body_inv_mass[i]
    inv_mj = model.body_inv_mass[j]
    if wp.max(heavy_partner_mass(inv_mi, inv_mj), heavy_partner_mass(inv_mj, inv_mi)) == 0.0:
        return
    light = wp.where(inv_mi > inv_mj, i, j)
    if solver.terrain_row_count[light] == 0:
        return
    reach_i = wp.length(model.body_size[i])
    reach_j = wp.length(model.body_size[j])
    for _pass in range(CHAIN_PASSES - 1):
        before = read_pair_velocity(solver, i, j)
        sweep_body_terrain(light, model, settings, 1, slots, solver)
        solve_one_pair(p, MODE_SOLVE, model, settings, pairs, solver, 0, -1)
        if pair_change(before, read_pair_velocity(solver, i, j), reach_i, reach_j) < settings.convergence_tolerance:
            break


# Push-out across a chain.  The relax converges a pair's points and a body's terrain rows each on
# their own; where a pushed body's partner rests on the ground, the pair's relax hands half the push
# to the partner, whose terrain rows then stop it, and the rest stayed (a unit cube started 2 cm
# into another on the plane left at 0.51 m/s).  So after its relax a pair walks its bodies'
# terrain rows and its own points again, up to CHAIN_PASSES - 1 times, until a pass moves neither
# body by more than the tolerance: each pass hands back the share the last one left (half, for
# equal masses).  Only a pair whose relax let go of a push (relax_chain_needed) walks it.


@wp.func
def pair_normal_total(p: int, pairs: PairContacts) -> float:
    """The normal impulse pair p's points hold together."""
    total = float(0.0)
    for k in range(pairs.pair_point_count[p]):
        total += pairs.pair_normal_impulse[p * POINTS + k]
    return total


@wp.func
def relax_chain_needed(p: int, held: float, model: BodyModel, settings: StepSettings, pairs: PairContacts,
                       solver: SolverBodies) -> int:
    """1 when pair p's relax let go of enough normal impulse (``held`` before it) to move its bodies
    apart by RELAX_CHAIN_TOLERANCES tolerances or more, with one of them, dynamic, holding terrain
    rows to hand the change to.

    The speed the relax takes back is the normal impulse let go times 1/m_i + 1/m_j (less at an
    arm, where the bodies also turn): what a push leaves, unlike a change of friction or spin,
    which the first trigger tried (any velocity change of |g| h) also counted."""
    if settings.relax_passes <= 1:
        return 0  # Box2D's single relax, the faster choice, leaves part of every push (soft_step.py)
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    inv_mi = model.body_inv_mass[i]
    inv_mj = model.body_inv_mass[j]
    if not ((inv_mi > 0.0 and solver.terrain_row_count[i] > 0) or (inv_mj > 0.0 and solver.terrain_row_count[j] > 0)):
        return 0
    released = (held - pair_normal_total(p, pairs)) * (inv_mi + inv_mj)
    return int(released >= RELAX_CHAIN_TOLERANCES * settings.convergence_tolerance)


@wp.func
def relax_chain_pair(
    p: int,
    mode: int,
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in/out
    pairs: PairContacts,
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
):
    """After pair p's relax (MODE_RELAX or MODE_RELAX_CLOSED): its bodies' terrain rows and its points
    again, until a pass moves neither body by more than the tolerance (comment above)."""
    ij = pairs.pair_body[p]
    i = ij[0]
    j = ij[1]
    use_bias = wp.where(mode == MODE_RELAX_CLOSED, -1, 0)
    reach_i = wp.length(model.body_size[i])
    reach_j = wp.length(model.body_size[j])
    for _pass in range(CHAIN_PASSES - 1):
        before = read_pair_velocity(solver, i, j)
        sweep_body_terrain(i, model, settings, use_bias, slots, solver)
        sweep_body_terrain(j, model, settings, use_bias, slots, solver)
        solve_one_pair(p, mode, model, settings, pairs, solver, 0, -1)
        if pair_change(before, read_pair_velocity(solver, i, j), reach_i, reach_j) < settings.convergence_tolerance:
            break


@wp.kernel
def chain_pass(
    tid_offset: int,
    mode: int,
    color: int,
    color_start: wp.array(dtype=wp.int32),
    color_pairs_sorted: wp.array(dtype=wp.int32),
    # Model
    model: BodyModel,
    # Settings
    settings: StepSettings,
    # Contacts in/out
    pairs: PairContacts,
    slots: TerrainContacts,
    # Solver in/out
    solver: SolverBodies,
):
    """chain_pair over one colour after its solve launch (scenes whose dynamic masses differ 10-fold),
    or relax_chain_pair after its relax launch for the pairs that launch flagged (pair_relax_chain;
    scenes with terrain contacts): a kernel of its own,
    so pair_pass keeps its registers (the terrain sweep it inlines takes the kernel to the 255 cap
    on sm_90)."""
    r = color_range(color, color_start, wp.tid() + tid_offset)
    for index in range(r[0], r[1]):
        p = color_pairs_sorted[index]
        if mode == MODE_SOLVE:
            chain_pair(p, model, settings, pairs, slots, solver)
        elif pairs.pair_relax_chain[p] != 0:
            relax_chain_pair(p, mode, model, settings, pairs, slots, solver)


PAIR_PASS = {mode: pair_pass_for(mode) for mode in SWEEP_MODE_NAMES}
