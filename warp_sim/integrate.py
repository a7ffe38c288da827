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

Rotation: the ODE Y' = f(Y) for Y = R (matrix modes, f = skew(omega(R)) R) or Y = q
(quaternion mode, f = 1/2 [omega, 0] q) is stepped with the integrator's own scheme:

    explicit_euler, semi_implicit   Y' = Y + h f(Y)                    order 1
    verlet                          Y' = Y + h f(Y + h/2 f(Y))         order 2 (explicit midpoint:
                                    omega depends on R, so position-Verlet's split does not apply)
    rk4                             classic 4-stage Runge-Kutta        order 4

Stage values use the additive update the thesis describes (S + h dS), never an exponential map,
so each method's own error, and the drift of an unrepaired matrix, stay visible.  The repair
after the step is chosen separately (``rotation``): quaternion renormalisation, none (``matrix``),
cross-product re-orthonormalisation (``matrix_cross``) or Gram-Schmidt.
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


@wp.func
def pre_kick_fraction(integrator: int) -> float:
    if integrator == INTEGRATOR_EXPLICIT_EULER:
        return 0.0
    if integrator == INTEGRATOR_SEMI_IMPLICIT:
        return 1.0
    return 0.5


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
    k1 = matrix_derivative(rot, inv_inertia, angmom)
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
    if rotation == ROTATION_QUATERNION:
        q_new = wp.normalize(step_quat(q, inv_inertia, angmom, h, integrator))
        return q_new, wp.quat_to_matrix(q_new)
    r_new = step_matrix(rot, inv_inertia, angmom, h, integrator)
    if rotation == ROTATION_MATRIX_CROSS:
        r_new = orthonormalize_cross(r_new)
    elif rotation == ROTATION_MATRIX_GRAM_SCHMIDT:
        r_new = orthonormalize_gram_schmidt(r_new)
    return wp.normalize(wp.quat_from_matrix(r_new)), r_new

