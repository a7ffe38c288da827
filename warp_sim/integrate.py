"""Time integration of the rigid-body state (SEED.md 2).

State S = (x, R or q, P = m v, L).  Torque-free, dS/dt = (v, omega* R, m g, 0) with
omega = R I_body^-1 R^T L: angular momentum is the stored variable, so the gyroscopic effect
is exact by construction (L is constant in free flight, omega turns as R turns) and a box spun
near its intermediate axis flips (Dzhanibekov).

Translation: gravity is the only smooth force and contact impulses act at the start of a
substep, so every integrator is a "kick - drift - kick" with pre-kick fraction alpha:

    v* = v + alpha g h;   contacts solved on v*;   x' = x + h v*;   v' = v* + (1 - alpha) g h

    explicit_euler  alpha = 0    x' = x + h v             (the thesis's; error -g t h / 2)
    semi_implicit   alpha = 1    x' = x + h (v + g h)     (symplectic Euler; error +g t h / 2)
    verlet, rk4     alpha = 1/2  x' = x + h v + g h^2 / 2 (exact for constant g)

so the contact solver always works on the velocity that moves the body.

``semi_implicit``, the default, kicks the whole substep's gravity before the contacts so that a
body they hold keeps a stored velocity of 0 (under alpha = 1/2 a resting body reads g h / 2).
Its drift x + h (v + g h) then runs g h^2 / 2 ahead of the parabola every substep, which in
flight is a steady loss of energy, m g^2 h / 2 a second: a ball bouncing with e = 1 on the
terrain lost 12 % of its energy in 10 s at the defaults (2 m drops), and a projectile lands
g t h / 2 short of where it should.  A body that no contact touched in the substep (its solved
velocity is exactly the kicked one, nothing turned it, no impact struck it: ``free_drift``) has
only gravity acting on it, so its drift is taken as the parabola's, x + h v + g h^2 / 2, exact.
A body any contact touched keeps symplectic Euler's drift, whose velocity is the one the solve
left: what the contacts hold is not moved by the correction.

Rotation: the ODE Y' = f(Y) for Y = R (matrix modes, f = skew(omega(R)) R) or Y = q
(quaternion mode, f = 1/2 [omega, 0] q) is stepped with the integrator's own scheme:

    explicit_euler                  Y' = Y + h f(Y)                    order 1 (the thesis's;
                                    gains energy: +35 % in 20 s on a tumbling 1x2x3 box)
    semi_implicit                   implicit midpoint in the body frame (below)  order 2
    verlet                          Y' = Y + h f(Y + h/2 f(Y))         order 2 (explicit midpoint:
                                    omega depends on R, so position-Verlet's split does not apply)
    rk4                             classic 4-stage Runge-Kutta        order 4

The explicit stages use the additive update the thesis describes (S + h dS), never an
exponential map, so each method's own error, and the drift of an unrepaired matrix, stay visible.

``semi_implicit`` is the default, so it must keep free-flight energy: it used to share explicit
Euler's update, which multiplies |omega| by sqrt(1 + (h omega)^2) per step (a box tumbling
near its middle axis gained 35 % kinetic energy in 20 s and flipped 14 times instead of 3).
It now takes the implicit midpoint rule of Euler's equations for the body-frame momentum
Lb = R^T L (the Lie-Poisson midpoint rule):

    m = Lb - h/2 (I^-1 m) x m          (m = (Lb + Lb') / 2, solved by Newton, 2-3 iterations)
    R' = R cay(h I^-1 m)               (cay(a) = rotation of quaternion (a/2, 1) / |(a/2, 1)|)

cay is exactly orthogonal and Lb' = cay^T Lb is the midpoint rule's own update, so world L is
untouched (R' Lb' = L), |Lb| is exact and the energy 1/2 Lb.I^-1 Lb is exact too (its change is
(Lb' - Lb).I^-1 m, a cross product dotted with one of its factors); what is left is the Newton
residual and float32 round-off.  The orientation error is second order.  For spheres and cubes
(isotropic inertia) m = Lb at once and the update is the exact rotation by 2 atan(h |omega| / 2).

The repair after the step is chosen separately (``rotation``): quaternion renormalisation, none
(``matrix``), cross-product re-orthonormalisation (``matrix_cross``) or Gram-Schmidt.
"""

import warp as wp

from .types import (
    INTEGRATOR_EXPLICIT_EULER,
    INTEGRATOR_RK4,
    INTEGRATOR_SEMI_IMPLICIT,
    INTEGRATOR_VERLET,
    ROTATION_MATRIX_CROSS,
    ROTATION_MATRIX_GRAM_SCHMIDT,
    ROTATION_QUATERNION,
)


# alpha by integrator name, for the host (pre_kick_fraction is the kernels')
PRE_KICK_FRACTION = {"explicit_euler": 0.0, "semi_implicit": 1.0, "verlet": 0.5, "rk4": 0.5}


@wp.func
def pre_kick_fraction(integrator: int) -> float:
    if integrator == INTEGRATOR_EXPLICIT_EULER:
        return 0.0
    if integrator == INTEGRATOR_SEMI_IMPLICIT:
        return 1.0
    return 0.5


@wp.func
def same_vector(a: wp.vec3, b: wp.vec3) -> bool:
    return a[0] == b[0] and a[1] == b[1] and a[2] == b[2]


@wp.func
def free_drift(integrator: int, untouched: bool, gravity: wp.vec3, h: float) -> wp.vec3:
    """What a ``semi_implicit`` drift of a body no contact touched this substep is moved by so that
    it follows the parabola exactly: -g h^2 / 2 (module docstring); nothing otherwise."""
    if integrator == INTEGRATOR_SEMI_IMPLICIT and untouched:
        return (-0.5 * h * h) * gravity
    return wp.vec3(0.0)


@wp.func
def world_inv_inertia(rot: wp.mat33, inv_inertia: wp.vec3) -> wp.mat33:
    """I(t)^-1 = R I_body^-1 R^T (uses R^T as the thesis does, also for a drifted R)."""
    return rot * wp.diag(inv_inertia) * wp.transpose(rot)


@wp.func
def world_inertia(rot: wp.mat33, inertia: wp.vec3) -> wp.mat33:
    return rot * wp.diag(inertia) * wp.transpose(rot)


@wp.func
def matrix_derivative(rot: wp.mat33, inv_inertia: wp.vec3, angmom: wp.vec3) -> wp.mat33:
    omega = world_inv_inertia(rot, inv_inertia) * angmom
    return wp.skew(omega) * rot


@wp.func
def quat_derivative(q: wp.quat, inv_inertia: wp.vec3, angmom: wp.vec3) -> wp.quat:
    rot = wp.quat_to_matrix(wp.normalize(q))
    omega = world_inv_inertia(rot, inv_inertia) * angmom
    return 0.5 * (wp.quat(omega[0], omega[1], omega[2], 0.0) * q)


@wp.func
def orthonormalize_cross(rot: wp.mat33) -> wp.mat33:
    """SEED.md 2(a): keep the x axis direction, rebuild z = x cross y, then y = z cross x."""
    x = wp.normalize(wp.vec3(rot[0, 0], rot[1, 0], rot[2, 0]))
    y = wp.vec3(rot[0, 1], rot[1, 1], rot[2, 1])
    z = wp.normalize(wp.cross(x, y))
    y = wp.cross(z, x)
    return wp.matrix_from_cols(x, y, z)


@wp.func
def orthonormalize_gram_schmidt(rot: wp.mat33) -> wp.mat33:
    """SEED.md 2(b): u_k = v_k - sum_j proj_{u_j} v_k, normalised, over the columns."""
    v1 = wp.vec3(rot[0, 0], rot[1, 0], rot[2, 0])
    v2 = wp.vec3(rot[0, 1], rot[1, 1], rot[2, 1])
    v3 = wp.vec3(rot[0, 2], rot[1, 2], rot[2, 2])
    u1 = wp.normalize(v1)
    u2 = wp.normalize(v2 - wp.dot(v2, u1) * u1)
    u3 = wp.normalize(v3 - wp.dot(v3, u1) * u1 - wp.dot(v3, u2) * u2)
    return wp.matrix_from_cols(u1, u2, u3)


@wp.func
def step_matrix(rot: wp.mat33, inv_inertia: wp.vec3, angmom: wp.vec3, h: float, integrator: int) -> wp.mat33:
    k1 = matrix_derivative(rot, inv_inertia, angmom)  # semi_implicit never gets here
    if integrator == INTEGRATOR_VERLET:
        k2 = matrix_derivative(rot + (0.5 * h) * k1, inv_inertia, angmom)
        return rot + h * k2
    if integrator == INTEGRATOR_RK4:
        k2 = matrix_derivative(rot + (0.5 * h) * k1, inv_inertia, angmom)
        k3 = matrix_derivative(rot + (0.5 * h) * k2, inv_inertia, angmom)
        k4 = matrix_derivative(rot + h * k3, inv_inertia, angmom)
        return rot + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return rot + h * k1


@wp.func
def step_quat(q: wp.quat, inv_inertia: wp.vec3, angmom: wp.vec3, h: float, integrator: int) -> wp.quat:
    k1 = quat_derivative(q, inv_inertia, angmom)
    if integrator == INTEGRATOR_VERLET:
        k2 = quat_derivative(q + (0.5 * h) * k1, inv_inertia, angmom)
        return q + h * k2
    if integrator == INTEGRATOR_RK4:
        k2 = quat_derivative(q + (0.5 * h) * k1, inv_inertia, angmom)
        k3 = quat_derivative(q + (0.5 * h) * k2, inv_inertia, angmom)
        k4 = quat_derivative(q + h * k3, inv_inertia, angmom)
        return q + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
    return q + h * k1


# Newton on m - Lb + h/2 (I^-1 m) x m = 0 from m = Lb: the error squares each iteration, from
# (h omega)^2 |Lb| after the first, so 4 reach float32 round-off up to h omega ~ 1 (a box hit hard);
# the loop stops once the residual is at round-off (spheres and cubes: before the first).
MIDPOINT_NEWTON_ITERATIONS = wp.constant(4)
MIDPOINT_RESIDUAL = wp.constant(2.0e-7)  # relative to |Lb|: float32 eps plus one rounding


@wp.func
def midpoint_body_omega(angmom_body: wp.vec3, inv_inertia: wp.vec3, h: float) -> wp.vec3:
    """Body-frame angular velocity I^-1 m at the midpoint of the step (see the module docstring)."""
    m = angmom_body
    tol = MIDPOINT_RESIDUAL * wp.length(angmom_body)
    for _it in range(MIDPOINT_NEWTON_ITERATIONS):
        w = wp.cw_mul(inv_inertia, m)
        g = m - angmom_body + (0.5 * h) * wp.cross(w, m)
        if wp.length(g) <= tol:
            break
        # d/dm (I^-1 m) x m = skew(I^-1 m) - skew(m) I^-1
        jac = wp.identity(n=3, dtype=float) + (0.5 * h) * (wp.skew(w) - wp.skew(m) * wp.diag(inv_inertia))
        m = m - wp.inverse(jac) * g
    return wp.cw_mul(inv_inertia, m)


@wp.func
def cayley_quat(omega_body: wp.vec3, h: float) -> wp.quat:
    a = (0.5 * h) * omega_body
    return wp.normalize(wp.quat(a[0], a[1], a[2], 1.0))


@wp.func
def integrate_rotation(
    q: wp.quat,
    rot: wp.mat33,
    inv_inertia: wp.vec3,
    angmom: wp.vec3,
    h: float,
    integrator: int,
    rotation: int,
) -> tuple[wp.quat, wp.mat33]:
    """Advance the orientation one step; returns the (quat, matrix) pair kept consistent.

    In matrix modes the quaternion is derived from the matrix for output only.
    """
    if integrator == INTEGRATOR_SEMI_IMPLICIT:
        omega_body = midpoint_body_omega(wp.transpose(rot) * angmom, inv_inertia, h)
        turn = cayley_quat(omega_body, h)
        if rotation == ROTATION_QUATERNION:
            q_mid = wp.normalize(q * turn)  # body-frame increment multiplies on the right
            return q_mid, wp.quat_to_matrix(q_mid)
        r_mid = rot * wp.quat_to_matrix(turn)
        if rotation == ROTATION_MATRIX_CROSS:
            r_mid = orthonormalize_cross(r_mid)
        elif rotation == ROTATION_MATRIX_GRAM_SCHMIDT:
            r_mid = orthonormalize_gram_schmidt(r_mid)
        return wp.normalize(wp.quat_from_matrix(r_mid)), r_mid
    if rotation == ROTATION_QUATERNION:
        q_new = wp.normalize(step_quat(q, inv_inertia, angmom, h, integrator))
        return q_new, wp.quat_to_matrix(q_new)
    r_new = step_matrix(rot, inv_inertia, angmom, h, integrator)
    if rotation == ROTATION_MATRIX_CROSS:
        r_new = orthonormalize_cross(r_new)
    elif rotation == ROTATION_MATRIX_GRAM_SCHMIDT:
        r_new = orthonormalize_gram_schmidt(r_new)
    return wp.normalize(wp.quat_from_matrix(r_new)), r_new

