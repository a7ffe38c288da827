"""Rolling resistance of a sphere's contact: an angular impulse against its spin, clamped to
c_r r j_n (soft_step.py's rows, staged.py's and pair_solve.py's), and the hold that stops a ball
at once where friction and the resistance together can."""

from typing import Any

import warp as wp

from .body_velocity import BodyVelocity
from .pair_geometry import PairVelocity

wp.set_module_options({"enable_backward": False})


@wp.struct
class RollingHold:
    """hold_ball's outcome: the velocities, the contact's accumulated tangential impulse, and
    whether the ball was held."""

    vel: BodyVelocity
    tangent_impulse: wp.vec3
    held: int


@wp.func
def isotropic_inverse(inv_inertia: float) -> float:
    """A sphere's inverse inertia as the scalar it is (the matrix of the staged path is d 1)."""
    return inv_inertia


@wp.func
def isotropic_inverse(inv_inertia: wp.mat33) -> float:
    return inv_inertia[0, 0]


@wp.func
def hold_ball(vel: BodyVelocity, n: wp.vec3, arm: wp.vec3, inv_mass: float, inv_inertia: float, friction: float,
              rolling_limit: float, normal_impulse: float, tangent_impulse: wp.vec3) -> RollingHold:
    """A ball on a contact held still at once, where friction and rolling resistance can: the
    tangential impulse P that stops its centre along the contact plane and the angular impulse M
    that stops its spin, P = -m v_t and M = -I w - arm x P, when |P_acc| <= mu N and
    |M_acc| <= c_r r N.  Taken as two rows in turn (friction, then solve_rolling) the rows undo each
    other (stopping the contact point sets the ball rolling; stopping the roll sets the point
    sliding), and two sweeps leave a ball on a slope gentler than c_r creeping at about
    0.6 g sin(theta) h (2.7 mm/s at the defaults, c_r 0.1, 1 degree under it).  Otherwise
    ``held`` is 0 and the rows run as before."""
    out = RollingHold()
    out.vel = vel
    out.tangent_impulse = tangent_impulse
    out.held = 0
    v_t = vel.v - wp.dot(vel.v, n) * n
    push = -v_t / inv_mass
    turn = -vel.w / inv_inertia - wp.cross(arm, push)
    tangent = tangent_impulse + push
    rolling = vel.rolling_impulse + turn
    if wp.length(tangent) <= friction * normal_impulse and wp.length(rolling) <= rolling_limit * normal_impulse:
        out.vel.v = vel.v - v_t
        out.vel.w = wp.vec3(0.0)
        out.vel.rolling_impulse = rolling
        out.tangent_impulse = tangent
        out.held = 1
    return out


@wp.struct
class PairHold:
    """hold_ball_on_static's outcome, in the pair's terms (impulses on body i)."""

    vel: PairVelocity
    tangent_impulse: wp.vec3
    rolling_impulse: wp.vec3
    held: int


@wp.func
def static_ball_side(rolling_arm_i: float, rolling_arm_j: float, inv_mass_i: float, inv_mass_j: float) -> int:
    """+1 where body i is a ball with rolling resistance on a static j, -1 the other way round, else
    0: the pairs hold_ball_on_static holds.  (A ball on a moving body keeps the rows in turn: holding
    it would need the 6 x 6 system of both bodies' velocities.)"""
    if rolling_arm_i > 0.0 and inv_mass_j == 0.0:
        return 1
    if rolling_arm_j > 0.0 and inv_mass_i == 0.0:
        return -1
    return 0


@wp.func
def hold_ball_on_static(vel: PairVelocity, ball_side: int, n: wp.vec3, ri: wp.vec3, rj: wp.vec3, inv_mi: float,
                        inv_mj: float, inv_ii: wp.mat33, inv_ij: wp.mat33, friction: float, rolling_limit: float,
                        normal_impulse: float, tangent_impulse: wp.vec3, rolling_impulse: wp.vec3) -> PairHold:
    """hold_ball for a ball's pair contact with a static body (a box floor): the static side does
    not move, so the ball is held still as on the terrain.  Without it friction and rolling
    resistance, taken in turn, undid each other here too: a ball on a static box tilted 1 degree
    under atan(c_r) (c_r 0.1) crept 13 mm in 5 s.  Taken in the solve sweeps only: the relax starts
    from a held ball and the hold there changed nothing but the relax kernels' registers.  The pair
    stores impulses on body i; the ball's are those times ``ball_side``."""
    side = float(ball_side)
    ball = BodyVelocity()
    ball.rolling_impulse = side * rolling_impulse
    arm = ri
    inv_mass = inv_mi
    inv_inertia = isotropic_inverse(inv_ii)
    ball.v = vel.vi
    ball.w = vel.wi
    if ball_side < 0:
        arm = rj
        inv_mass = inv_mj
        inv_inertia = isotropic_inverse(inv_ij)
        ball.v = vel.vj
        ball.w = vel.wj
    hold = hold_ball(ball, n, arm, inv_mass, inv_inertia, friction, rolling_limit, normal_impulse,
                     side * tangent_impulse)
    out = PairHold()
    out.vel = vel
    out.tangent_impulse = tangent_impulse
    out.rolling_impulse = rolling_impulse
    out.held = hold.held
    if hold.held != 0:
        out.tangent_impulse = side * hold.tangent_impulse
        out.rolling_impulse = side * hold.vel.rolling_impulse
        if ball_side > 0:
            out.vel.vi = hold.vel.v
            out.vel.wi = hold.vel.w
        else:
            out.vel.vj = hold.vel.v
            out.vel.wj = hold.vel.w
    return out


@wp.func
def solve_rolling(
    vel: BodyVelocity,
    n: wp.vec3,
    inv_inertia: Any,
    limit: float,
) -> BodyVelocity:
    """Angular impulse against the spin (rolling and twisting about n), accumulated, clamped to ``limit``.

    Real contacts resist both (rolling resistance and torsional friction); resisting only the
    rolling part leaves a ball spinning in place on its contact point forever.
    """
    acc = vel.rolling_impulse
    roll = vel.w
    # against the spin w with the mass 1 / (a . I^-1 a) of its axis a = w / |w|:
    # Delta = -(|w| / a . I^-1 a) a = -(|w|^2 / w . I^-1 w) w, with no square root; the clamp
    # takes one only when it bites
    speed2 = wp.dot(roll, roll)
    new_acc = acc
    if speed2 > 1.0e-18:
        new_acc = acc - (speed2 / wp.dot(roll, inv_inertia * roll)) * roll
    mag2 = wp.dot(new_acc, new_acc)
    if mag2 > limit * limit:
        new_acc = new_acc * (limit / wp.sqrt(mag2))
    out = vel
    out.w = vel.w + inv_inertia * (new_acc - acc)
    out.rolling_impulse = new_acc
    return out
