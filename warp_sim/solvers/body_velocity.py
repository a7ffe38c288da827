"""A body's velocities while its contacts are solved, and the impulses that change them."""

from typing import Any

import warp as wp

from ..collide.contact_patch import twist_arm

wp.set_module_options({"enable_backward": False})


@wp.struct
class BodyVelocity:
    """A body's velocities while it is being solved, plus its rolling-resistance accumulator."""

    v: wp.vec3
    w: wp.vec3
    rolling_impulse: wp.vec3


@wp.func
def apply_impulse(
    vel: BodyVelocity, impulse: wp.vec3, arm: wp.vec3, inv_mass: float, inv_inertia: Any
) -> BodyVelocity:
    out = vel
    out.v = vel.v + inv_mass * impulse
    out.w = vel.w + inv_inertia * wp.cross(arm, impulse)
    return out


@wp.func
def apply_contact_impulse(vel: BodyVelocity, normal_part: wp.vec3, tangent_part: wp.vec3, arm: wp.vec3,
                          n: wp.vec3, twist: wp.vec4, inv_mass: float, inv_inertia: Any) -> BodyVelocity:
    """A contact's stored impulse, its friction part at the patch's friction arm (contact_patch.py); as
    one impulse at ``arm`` where that is the arm itself.  A contact holding none (an idle
    speculative one: most of a settled box's) changes nothing and is skipped."""
    if twist[3] >= 1.0:
        return apply_impulse(vel, normal_part + tangent_part, arm, inv_mass, inv_inertia)
    if wp.length_sq(normal_part) == 0.0 and wp.length_sq(tangent_part) == 0.0:
        return vel
    out = vel
    out.v = vel.v + inv_mass * (normal_part + tangent_part)
    torque = wp.cross(arm, normal_part) + wp.cross(twist_arm(arm, arm, n, twist), tangent_part)
    out.w = vel.w + inv_inertia * torque
    return out
