"""A warm sphere's closest terrain point from one evaluation of the series, by its third-order jet.

A sphere's contact search (terrain_contact.sphere_fourier_closest) starts from last substep's
closest point p0.  Since then the centre c has moved by v h (a few millimetres for a ball
rolling at 1 m/s at 1/240 s), so Newton's first step delta is about that long, and nearly every
sphere of a rolling pile took a second evaluation of the series at p1 = p0 + delta only to find
the next step under the stopping tolerance (some a third).  The evaluation at p0 can carry the
third derivatives of H as well (four more sums a term), and with them where p1's step leads is
predicted, with a bound, without evaluating there.

The distance's half square and its derivatives, u = H(p) - c_y (H's own derivatives by index):

    F(p)        = |p - c_xz|^2 / 2 + u^2 / 2
    grad F      = p - c_xz + u grad H
    Hess F      = I + grad H grad H^T + u Hess H
    D3F[., a, a] = 2 (Hess H a) (grad H . a) + grad H (a^T Hess H a) + u D3H[., a, a]

Newton's step from p0 is delta = -Hess F(p0)^-1 grad F(p0), so by Taylor's theorem

    grad F(p1) = D3F(p0)[., delta, delta] / 2 + R,      |R| <= B4 |delta|^3 / 6,

B4 bounding F's fourth derivative on the segment: with G, K, T, Q bounding H's directional
derivatives of order 1 to 4 (FourierTerrain.directional_bound; a symmetric tensor's norm is
reached on a single direction) and |u| growing by at most G |delta| along it,

    B4 = 3 K^2 + 4 G T + (|u| + G |delta|) Q,      B3 = 3 G K + (|u| + G |delta|) T

(B3 bounds the third).  The predicted second move delta1 = -Hess F(p0)^-1 D3F[., delta, delta] / 2
differs from the Newton step at p1, -Hess F(p1)^-1 grad F(p1), by at most

    e = (|R| + B3 |delta| |delta1|) / lambda,

lambda the lowest eigenvalue of Hess F(p0) less B3 |delta| (Hess F moves by at most that on the
segment); and that Newton step lands within B3 |s|^2 / (2 lambda) of the closest point, s its
length (at most |delta1| + e).  The jet's point p2 = p1 + delta1 is taken when the sum of both is
under the search's own stopping tolerance: the full search stops at a point whose next step is
under it, so p2 is as near the closest point as the point the search would have stopped at.

The sample at p2 is H's Taylor polynomial of order 3 from p0 (Delta = delta + delta1): height
within Q |Delta|^4 / 24, gradient within Q |Delta|^3 / 6, which is required under the tolerance's
number too (a slope off by 1e-6 tilts the normal by 1e-6 rad).  At 4.6 mm (the median first step
of the 10k rolling spheres of bench/terrain_drop.py) that bound is 8e-8 on the shipped terrain.

Only a warm slot (the contact was found last substep) takes the jet; a cold search, whose first
step is long, and a step the search would clamp (to half its reach, or to the reach disc) keep
the full search.
"""

import warp as wp

from ..terrain import HeightSample


@wp.func
def third_along(third: wp.vec4, a: wp.vec2) -> wp.vec2:
    """D3H[., a, a]: the third derivatives (Hxxx, Hxxz, Hxzz, Hzzz) contracted twice with a."""
    return wp.vec2(third[0] * a[0] * a[0] + 2.0 * third[1] * a[0] * a[1] + third[2] * a[1] * a[1],
                   third[1] * a[0] * a[0] + 2.0 * third[2] * a[0] * a[1] + third[3] * a[1] * a[1])


@wp.func
def hessian_times(hess: wp.vec3, a: wp.vec2) -> wp.vec2:
    return wp.vec2(hess[0] * a[0] + hess[1] * a[1], hess[1] * a[0] + hess[2] * a[1])


@wp.func
def jet_sample(s: HeightSample, d: wp.vec2) -> HeightSample:
    """H's Taylor polynomial of order 3 from the sample ``s`` (third derivatives included), at
    offset ``d``: height, gradient and Hessian (errors Q|d|^4/24, Q|d|^3/6, Q|d|^2/2)."""
    kd = hessian_times(s.hess, d)
    td = third_along(s.third, d)
    out = HeightSample()
    out.height = s.height + wp.dot(s.grad, d) + 0.5 * wp.dot(kd, d) + wp.dot(td, d) / 6.0
    out.grad = s.grad + kd + 0.5 * td
    out.hess = s.hess + wp.vec3(s.third[0] * d[0] + s.third[1] * d[1], s.third[1] * d[0] + s.third[2] * d[1],
                                s.third[2] * d[0] + s.third[3] * d[1])
    out.third = s.third
    return out


@wp.struct
class JetStep:
    """The jet's outcome: ``accepted`` where p2 is as near the closest point as the search's
    stopping tolerance asks; then ``point`` (p2) and ``sample`` (its Taylor sample)."""

    accepted: int
    point: wp.vec2
    sample: HeightSample


@wp.func
def jet_step(s: HeightSample, xz: wp.vec2, u: float, delta: wp.vec2, hess_f: wp.vec3, tolerance: float,
             bounds: wp.vec4) -> JetStep:
    """The second Newton move predicted from the sample ``s`` at ``xz`` (u = H - c_y, ``delta`` the
    first move, ``hess_f`` = (a, b, c) of Hess F there, positive definite), accepted under the
    bounds of the module docstring.  ``bounds`` = (G, K, T, Q) of the terrain."""
    out = JetStep()
    out.accepted = 0
    g_bound = bounds[0]
    k_bound = bounds[1]
    t_bound = bounds[2]
    q_bound = bounds[3]
    length = wp.length(delta)
    u_far = wp.abs(u) + g_bound * length
    b3 = 3.0 * g_bound * k_bound + u_far * t_bound
    b4 = 3.0 * k_bound * k_bound + 4.0 * g_bound * t_bound + u_far * q_bound
    a = hess_f[0]
    b = hess_f[1]
    c = hess_f[2]
    lowest = 0.5 * (a + c) - wp.sqrt(0.25 * (a - c) * (a - c) + b * b) - b3 * length
    if lowest <= 0.0:
        return out
    kd = hessian_times(s.hess, delta)
    d3f = 2.0 * wp.dot(s.grad, delta) * kd + wp.dot(kd, delta) * s.grad + u * third_along(s.third, delta)
    g1 = 0.5 * d3f
    det = a * c - b * b
    delta1 = -wp.vec2((c * g1[0] - b * g1[1]) / det, (a * g1[1] - b * g1[0]) / det)
    length1 = wp.length(delta1)
    remainder = b4 * length * length * length / 6.0
    error = (remainder + b3 * length * length1) / lowest
    reach = length1 + error
    newton_left = b3 * reach * reach / (2.0 * lowest)
    total = delta + delta1
    span = wp.length(total)
    slope_error = q_bound * span * span * span / 6.0
    if error + newton_left < tolerance and slope_error < tolerance:
        out.accepted = 1
        out.point = xz + total
        out.sample = jet_sample(s, total)
    return out
