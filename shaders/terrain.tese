#version 410 core
#include "common.glsl"
#include "terrain_common.glsl"

// Every generated vertex gets its height, analytic normal and texture coordinate from the same
// coefficients and model transform (scale, offset) the physics uses.

layout(quads, fractional_even_spacing, ccw) in;

in vec2 c_xz[];

out vec3 te_world;     // world position [m]; also captured by transform feedback in the tests
out vec3 te_normal;    // unit normal
out vec2 te_texcoord;  // terrain-space (u, w): texture follows the terrain when it is scaled or moved

void main() {
    vec2 a = mix(c_xz[0], c_xz[1], gl_TessCoord.x);
    vec2 b = mix(c_xz[3], c_xz[2], gl_TessCoord.x);
    vec2 xz = mix(a, b, gl_TessCoord.y);
    TerrainSample s = terrain_sample(xz.x, xz.y);
    te_world = vec3(xz.x, s.height, xz.y);
    te_normal = terrain_normal(s.grad);
    te_texcoord = (xz - terrain_offset.xz) / terrain_scale.xz;
    gl_Position = camera_view_projection * vec4(te_world, 1.0);
}
