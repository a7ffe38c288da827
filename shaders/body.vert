#version 410 core
#include "common.glsl"

// Instanced spheres and boxes.  Per instance: the three columns of body_rot scaled by the shape's
// size (radius, or half-extents for a unit cube [-1, 1]^3) with the position in w, and a colour.
// body_rot may be non-orthonormal in the raw `matrix` rotation mode, so normals use the
// cofactor matrix (the inverse transpose up to a scale) and a drifting box visibly stretches.

layout(location = 0) in vec3 mesh_position;
layout(location = 1) in vec3 mesh_normal;
layout(location = 2) in vec4 instance_axis_x;  // xyz: scaled first column, w: position x
layout(location = 3) in vec4 instance_axis_y;
layout(location = 4) in vec4 instance_axis_z;
layout(location = 5) in vec4 instance_color;

out vec3 b_world;
out vec3 b_normal;
out vec3 b_local;
out vec4 b_color;

void main() {
    mat3 m = mat3(instance_axis_x.xyz, instance_axis_y.xyz, instance_axis_z.xyz);
    vec3 position = vec3(instance_axis_x.w, instance_axis_y.w, instance_axis_z.w);
    mat3 cofactor = mat3(cross(m[1], m[2]), cross(m[2], m[0]), cross(m[0], m[1]));
    float det_sign = dot(m[0], cofactor[0]) < 0.0 ? -1.0 : 1.0;
    b_world = m * mesh_position + position;
    b_normal = det_sign * (cofactor * mesh_normal);
    b_local = mesh_position;
    b_color = instance_color;
    gl_Position = camera_view_projection * vec4(b_world, 1.0);
}
