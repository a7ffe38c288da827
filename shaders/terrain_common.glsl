// The terrain height function, mirrored line by line from warp_sim/terrain.py (fourier_sample).
//
//   H(x, z) = o.y + s.y * sum_{m,n<k} Re(C(m,n) e^{i f m u} e^{i f n w}),  u = (x - o.x)/s.x, w = (z - o.z)/s.z
//
// C(m,n) = A e^{i(P + phase)} comes from FourierTerrain.complex_coefficients(), uploaded unchanged
// (two complex numbers per vec4).  As in Warp, two sincos calls give e^{i f u} and e^{i f w} and the
// powers follow by complex multiplication.  The plane terrain n.p <= d is drawn by the same pipeline.

#define TERRAIN_NONE 0
#define TERRAIN_PLANE 1
#define TERRAIN_FOURIER 2
#define TERRAIN_MAX_TERMS 32

layout(std140) uniform Terrain {
    ivec4 terrain_info;     // kind, terms k, frustum culling on/off, patches per side
    vec4 terrain_params;    // frequency f [rad/m of terrain space], height bound [m], contour spacing [m], grid line spacing [m]
    vec4 terrain_scale;     // s.xyz
    vec4 terrain_offset;    // o.xyz
    vec4 terrain_plane;     // plane normal n.xyz, offset d
    vec4 terrain_tess;      // min depth, max depth [m], min level, max level
    vec4 terrain_grid;      // grid origin x, z [m], patch size [m], unused
    vec4 terrain_coef[TERRAIN_MAX_TERMS * TERRAIN_MAX_TERMS / 2];
};

struct TerrainSample {
    float height;  // world height H [m]
    vec2 grad;     // (dH/dx, dH/dz)
};

vec2 terrain_coefficient(int index) {
    vec4 pair = terrain_coef[index / 2];
    return (index % 2) == 0 ? pair.xy : pair.zw;
}

TerrainSample fourier_sample(float x, float z) {
    int k = terrain_info.y;
    float f = terrain_params.x;
    float u = (x - terrain_offset.x) / terrain_scale.x;
    float w = (z - terrain_offset.z) / terrain_scale.z;
    vec2 ex = vec2(cos(f * u), sin(f * u));
    vec2 ez = vec2(cos(f * w), sin(f * w));
    float h = 0.0;
    float hu = 0.0;
    float hw = 0.0;
    vec2 pm = vec2(1.0, 0.0);
    for (int m = 0; m < k; ++m) {
        vec2 pn = pm;
        float fm = f * float(m);
        for (int n = 0; n < k; ++n) {
            vec2 c = terrain_coefficient(m * k + n);
            float re = c.x * pn.x - c.y * pn.y;
            float im = c.x * pn.y + c.y * pn.x;
            float fn = f * float(n);
            h += re;
            hu -= fm * im;
            hw -= fn * im;
            pn = vec2(pn.x * ez.x - pn.y * ez.y, pn.x * ez.y + pn.y * ez.x);
        }
        pm = vec2(pm.x * ex.x - pm.y * ex.y, pm.x * ex.y + pm.y * ex.x);
    }
    TerrainSample s;
    s.height = terrain_offset.y + terrain_scale.y * h;
    s.grad = vec2(hu * terrain_scale.y / terrain_scale.x, hw * terrain_scale.y / terrain_scale.z);
    return s;
}

TerrainSample plane_sample(float x, float z) {
    // n.p = d solved for y; vertical planes cannot be drawn as a heightfield (ny is clamped).
    vec3 n = terrain_plane.xyz;
    float ny = abs(n.y) > 1e-4 ? n.y : 1e-4;
    TerrainSample s;
    s.height = (terrain_plane.w - n.x * x - n.z * z) / ny;
    s.grad = vec2(-n.x / ny, -n.z / ny);
    return s;
}

TerrainSample terrain_sample(float x, float z) {
    if (terrain_info.x == TERRAIN_PLANE) {
        return plane_sample(x, z);
    }
    return fourier_sample(x, z);
}

// Upward unit normal of y = H(x, z), as fourier_normal in Warp.
vec3 terrain_normal(vec2 grad) {
    return normalize(vec3(-grad.x, 1.0, -grad.y));
}

// A height no part of the surface near (x, z) is far from; used for culling and level-of-detail.
float terrain_base_height(float x, float z) {
    if (terrain_info.x == TERRAIN_PLANE) {
        return plane_sample(x, z).height;
    }
    return terrain_offset.y;
}
