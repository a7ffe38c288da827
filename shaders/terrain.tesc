#version 410 core
#include "common.glsl"
#include "terrain_common.glsl"

// Level of detail from camera distance (SEED.md 6).  Each OUTER level depends only on its edge's
// midpoint, which both patches sharing the edge compute from the same two corners: the levels
// agree, the edge vertices coincide and no cracks open.  Inner levels take the larger of the two
// outer levels that run in the same direction.

layout(vertices = 4) out;

in vec2 v_xz[];
out vec2 c_xz[];

float edge_level(vec2 a, vec2 b) {
    vec2 mid = 0.5 * (a + b);
    vec3 p = vec3(mid.x, terrain_base_height(mid.x, mid.y), mid.y);
    float d = distance(p, camera_eye.xyz);
    float t = clamp((d - terrain_tess.x) / max(terrain_tess.y - terrain_tess.x, 1e-6), 0.0, 1.0);
    return mix(terrain_tess.w, terrain_tess.z, t);
}

// True when the patch's bounding box (heights within the terrain's bound) is outside one clip plane.
bool patch_culled() {
    if (terrain_info.z == 0) {
        return false;
    }
    vec2 lo = min(min(v_xz[0], v_xz[1]), min(v_xz[2], v_xz[3]));
    vec2 hi = max(max(v_xz[0], v_xz[1]), max(v_xz[2], v_xz[3]));
    float y0 = 1e30;
    float y1 = -1e30;
    for (int i = 0; i < 4; ++i) {
        float base = terrain_base_height(v_xz[i].x, v_xz[i].y);
        y0 = min(y0, base);
        y1 = max(y1, base);
    }
    y0 -= terrain_params.y;
    y1 += terrain_params.y;
    bool left = true, right = true, bottom = true, top = true, near = true, far = true;
    for (int i = 0; i < 8; ++i) {
        vec3 p = vec3((i & 1) == 0 ? lo.x : hi.x, (i & 2) == 0 ? y0 : y1, (i & 4) == 0 ? lo.y : hi.y);
        vec4 c = camera_view_projection * vec4(p, 1.0);
        left = left && c.x < -c.w;
        right = right && c.x > c.w;
        bottom = bottom && c.y < -c.w;
        top = top && c.y > c.w;
        near = near && c.z < -c.w;
        far = far && c.z > c.w;
    }
    return left || right || bottom || top || near || far;
}

void main() {
    c_xz[gl_InvocationID] = v_xz[gl_InvocationID];
    if (gl_InvocationID == 0) {
        if (patch_culled()) {
            gl_TessLevelOuter[0] = 0.0;
            gl_TessLevelOuter[1] = 0.0;
            gl_TessLevelOuter[2] = 0.0;
            gl_TessLevelOuter[3] = 0.0;
            gl_TessLevelInner[0] = 0.0;
            gl_TessLevelInner[1] = 0.0;
        } else {
            // Quad domain: outer 0 is the u = 0 edge (corners 0-3), 1 is v = 0 (0-1),
            // 2 is u = 1 (1-2), 3 is v = 1 (3-2).
            gl_TessLevelOuter[0] = edge_level(v_xz[0], v_xz[3]);
            gl_TessLevelOuter[1] = edge_level(v_xz[0], v_xz[1]);
            gl_TessLevelOuter[2] = edge_level(v_xz[1], v_xz[2]);
            gl_TessLevelOuter[3] = edge_level(v_xz[3], v_xz[2]);
            gl_TessLevelInner[0] = max(gl_TessLevelOuter[1], gl_TessLevelOuter[3]);
            gl_TessLevelInner[1] = max(gl_TessLevelOuter[0], gl_TessLevelOuter[2]);
        }
    }
}
