#version 410 core
#include "common.glsl"
#include "terrain_common.glsl"

// Procedural material: grass on gentle slopes, rock on steep ones, snow high up, sand low down,
// plus contour lines (constant height) and a faint grid in terrain-space texture coordinates.

in vec3 te_world;
in vec3 te_normal;
in vec2 te_texcoord;

out vec4 frag_color;

// 1 on a line of period `spacing` in `value`, 0 away from it, one pixel wide (antialiased).
float line_mask(float value, float spacing) {
    float f = value / spacing;
    float d = abs(fract(f - 0.5) - 0.5) / max(fwidth(f), 1e-6);
    return 1.0 - min(d, 1.0);
}

void main() {
    vec3 n = normalize(te_normal);
    float slope = 1.0 - n.y;
    float bound = max(terrain_params.y, 1e-3);
    float rel = clamp((te_world.y - terrain_base_height(te_world.x, te_world.z)) / bound, -1.0, 1.0);

    vec3 grass = mix(vec3(0.24, 0.42, 0.16), vec3(0.36, 0.50, 0.20), 0.5 + 0.5 * rel);
    vec3 sand = vec3(0.66, 0.60, 0.44);
    vec3 rock = vec3(0.42, 0.39, 0.36);
    vec3 snow = vec3(0.93, 0.94, 0.97);
    vec3 albedo = mix(sand, grass, smoothstep(-0.75, -0.55, rel));
    albedo = mix(albedo, rock, smoothstep(0.12, 0.30, slope));
    albedo = mix(albedo, snow, smoothstep(0.45, 0.6, rel) * (1.0 - smoothstep(0.25, 0.45, slope)));

    if (terrain_params.z > 0.0) {
        albedo *= 1.0 - 0.45 * line_mask(te_world.y, terrain_params.z);
    }
    if (terrain_params.w > 0.0) {
        float grid = max(line_mask(te_texcoord.x, terrain_params.w), line_mask(te_texcoord.y, terrain_params.w));
        albedo *= 1.0 - 0.12 * grid;
    }
    vec3 color = blinn_phong(albedo, n, te_world, 0.15);
    frag_color = vec4(apply_fog(color, te_world), 1.0);
}
