#version 410 core
#include "common.glsl"

// Blinn-Phong with a pattern fixed to the body so that rotation is visible: darkened edges on
// boxes, an equator and a meridian on spheres.

uniform int shape_kind;  // 0 sphere, 1 box

in vec3 b_world;
in vec3 b_normal;
in vec3 b_local;
in vec4 b_color;

out vec4 frag_color;

void main() {
    vec3 n = normalize(b_normal);
    vec3 albedo = b_color.rgb;
    if (shape_kind == 1) {
        vec3 a = abs(b_local);
        // Second-largest coordinate near 1 means the fragment is close to an edge of the cube.
        float second = max(min(a.x, a.y), min(max(a.x, a.y), a.z));
        albedo *= mix(1.0, 0.55, smoothstep(0.86, 0.96, second));
    } else {
        float band = min(abs(b_local.y), abs(b_local.x));
        albedo *= mix(0.6, 1.0, smoothstep(0.06, 0.12, band));
    }
    vec3 color = blinn_phong(albedo, n, b_world, 0.6);
    frag_color = vec4(apply_fog(color, b_world), b_color.a);
}
