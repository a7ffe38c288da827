"""How fast a box's points could move within the step, for the windows its terrain slots open with.

Contacts found once per step open a terrain slot while its gap could close within the step
(terrain_contact.py).  A slot's approach at the pass misses what a contact event does to the box
mid-step: a plate landing on one edge pivots on it, and its far edge swings down.  So a box's
approach is at least the fastest any of its points could move after events that add no kinetic
energy: the most |v'| + |w'| R over m |v'|^2 / 2 + w' . I w' / 2 <= E is

    sqrt(2 E (1/m + R^2 / I_min))          (R its bounding radius, I_min its least principal moment)

with E its own kinetic energy (``reachable_speed``).  A box a partner strikes mid-step gains what
the pass did not see (a plate lying on the terrain, at rest, has nothing to reach with).  A blow
of restitution e <= 1 at relative speed v_rel gives a point of box b at most (1 + e) v_rel
k_b / (k_b + k_o) of speed, k the compliance 1/m + r^2 / I at the contact; bounded by
k_b = 1/m_b + R^2 / I_min (the most) and k_o >= 1/m_o (the least), and v_rel by the two bodies'
fastest points, |v_b - v_o| + |w_b| R_b + |w_o| R_o.  So after the pairs are found, each box in
a pair with a dynamic partner takes its own reach plus 2 v_rel k_b / (k_b + 1/m_o)
(``struck_reach``, one thread per pair, by atomic maximum: the same whatever the threads' order).
A pass therefore finds the pairs first and the terrain slots after, each box's windows opened with
the larger of the two reaches (collide_terrain's ``struck``): one terrain launch.  (The terrain came
first once, and the boxes a partner widened were found a second time at the same pose; that second
launch cost 1.3 to 3.5 ms a step of the 10k rain.)  A gain that carries a point less than the
speculative margin within the step is left to the margin, the window's allowance for motion the
pass cannot predict: taken at any gain, the resting neighbours' jitter widened every box of a
settling rain.  Bodies falling together (v_rel ~ 0) widen nothing; taken on both bodies' energies
instead, the bound widened most boxes of a falling rain and cost it 11 % of its speed.
"""

import warp as wp

from ..kernel_args import BodyModel, BodyState, bind
from ..launch import gpu_blocks, launch
from ..types import SHAPE_SPHERE

wp.set_module_options({"enable_backward": False})


@wp.func
def twice_energy_per_mass(v: wp.vec3, angmom: wp.vec3, rot: wp.mat33, inv_inertia: wp.vec3, inv_mass: float) -> float:
    """2 KE / m of a body: |v|^2 + (L . w) / m, with w = R I^-1 R^T L."""
    body_l = wp.transpose(rot) * angmom
    return wp.dot(v, v) + inv_mass * wp.dot(body_l, wp.cw_mul(inv_inertia, body_l))


@wp.func
def reach_from_energy(twice_energy: float, inertia: wp.vec3, inv_mass: float, half: wp.vec3) -> float:
    """The fastest a box's point can move with 2 E / m = ``twice_energy`` (module docstring)."""
    least = wp.min(inertia[0], wp.min(inertia[1], inertia[2]))
    return wp.sqrt(twice_energy * (1.0 + wp.dot(half, half) / (inv_mass * least)))


@wp.func
def reachable_speed(v: wp.vec3, angmom: wp.vec3, rot: wp.mat33, inertia: wp.vec3, inv_inertia: wp.vec3,
                    inv_mass: float, half: wp.vec3) -> float:
    """The fastest any point of a box can move on its own kinetic energy (module docstring)."""
    return reach_from_energy(twice_energy_per_mass(v, angmom, rot, inv_inertia, inv_mass), inertia, inv_mass, half)


@wp.kernel
def body_reach_terms(
    tid_offset: int,
    # Model
    model: BodyModel,
    # State in
    state_in: BodyState,
    # Out
    body_reach_terms: wp.array(dtype=wp.vec4),
):
    """Per body, once per pass (split across threads): its own reach (0 for a sphere or a static
    body), its spin speed |w| R, its compliance bound k = 1/m + R^2 / I_min, and 1/m."""
    b = wp.tid() + tid_offset
    inv_mass = model.body_inv_mass[b]
    rot = state_in.body_rot[b]
    angmom = state_in.body_angmom[b]
    half = model.body_size[b]
    w = rot * wp.cw_mul(model.body_inv_inertia[b], wp.transpose(rot) * angmom)
    own = float(0.0)
    compliance = float(0.0)
    if model.body_shape[b] != SHAPE_SPHERE and inv_mass > 0.0:
        inertia = model.body_inertia[b]
        own = reachable_speed(state_in.body_vel[b], angmom, rot, inertia, model.body_inv_inertia[b], inv_mass, half)
        compliance = inv_mass + wp.dot(half, half) / wp.min(inertia[0], wp.min(inertia[1], inertia[2]))
    body_reach_terms[b] = wp.vec4(own, wp.length(w) * wp.length(half), compliance, inv_mass)


@wp.kernel
def struck_reach(
    tid_offset: int,
    # Contacts in
    pair_count: wp.array(dtype=wp.int32),
    pair_body: wp.array(dtype=wp.vec2i),
    pair_point_count: wp.array(dtype=wp.int32),
    # Settings
    least_gain: float,
    # State in
    body_vel: wp.array(dtype=wp.vec3),
    # In
    body_reach_terms: wp.array(dtype=wp.vec4),
    # Out
    body_struck_reach: wp.array(dtype=float),
):
    """One thread per pair slot (past the live count: return): each box of a pair whose partner is
    dynamic takes its own reach plus 2 v_rel k_b / (k_b + 1/m_o) (module docstring), by atomic
    maximum."""
    p = wp.tid() + tid_offset
    if p >= pair_count[0] or pair_point_count[p] == 0:
        return
    ij = pair_body[p]
    ti = body_reach_terms[ij[0]]
    tj = body_reach_terms[ij[1]]
    relative = wp.length(body_vel[ij[0]] - body_vel[ij[1]]) + ti[1] + tj[1]
    for side in range(2):
        mine = wp.where(side == 0, ti, tj)
        other = wp.where(side == 0, tj, ti)
        gain = 2.0 * mine[2] / (mine[2] + other[3]) * relative
        if mine[2] > 0.0 and other[3] > 0.0 and gain > least_gain:
            wp.atomic_max(body_struck_reach, ij[side], mine[0] + gain)


class StruckReach:
    """The per-body reach struck_reach finds, read by the terrain pass that follows the pairs."""

    def __init__(self, body_count: int, device):
        self.device = device
        self.body_count = body_count
        self.body_struck_reach = wp.zeros(max(body_count, 1), dtype=float, device=device)
        self.body_reach_terms = wp.zeros(max(body_count, 1), dtype=wp.vec4, device=device)

    def find(self, model_args, state, contacts, margin: float, sweep_time: float):
        """After a pass's pairs, before its terrain slots: the boxes' reach from their partners (0 where
        no partner widens it).  The pair launch is one launch, never split: atomics (launch.py)."""
        self.body_struck_reach.zero_()
        if contacts.pair_max == 0:
            return
        launch(body_reach_terms, self.body_count, key=self, device=self.device, inputs=[
            model_args, bind(BodyState, state, state), self.body_reach_terms])
        wp.launch(struck_reach, dim=contacts.pair_max, device=self.device, **gpu_blocks(self.device), inputs=[
            0, contacts.pair_count, contacts.pair_body, contacts.pair_point_count, margin / sweep_time, state.body_vel,
            self.body_reach_terms, self.body_struck_reach])
