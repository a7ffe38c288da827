// Uniform blocks shared by every program (std140; binding points are set from Python after
// linking, because GLSL 4.10 has no layout(binding) on blocks).  Matrices are column-major.

layout(std140) uniform Camera {
    mat4 camera_view;
    mat4 camera_projection;
    mat4 camera_view_projection;
    vec4 camera_eye;       // xyz: world position [m]
    vec4 camera_viewport;  // width, height [px], near, far [m]
};

layout(std140) uniform Light {
    vec4 light_direction;  // xyz: unit vector towards the light
    vec4 light_color;      // rgb, w: ambient factor
    vec4 light_specular;   // x: specular strength, y: Blinn-Phong exponent
    vec4 sky_color;        // rgb: clear and fog colour, w: fog density [1/m] (squared exponential)
};

// Blinn-Phong (SEED.md 6): L = m_a + m_d max(0, l.n) + m_s max(0, h.n)^gamma, h = (l + v) / |l + v|.
vec3 blinn_phong(vec3 albedo, vec3 n, vec3 world_pos, float specular_scale) {
    vec3 l = normalize(light_direction.xyz);
    vec3 v = normalize(camera_eye.xyz - world_pos);
    vec3 h = normalize(l + v);
    float diffuse = max(dot(l, n), 0.0);
    float specular = diffuse > 0.0 ? pow(max(dot(h, n), 0.0), light_specular.y) : 0.0;
    vec3 ambient = light_color.w * albedo * mix(vec3(0.55, 0.5, 0.45), sky_color.rgb, 0.5 + 0.5 * n.y);
    return ambient + light_color.rgb * (albedo * diffuse + specular_scale * light_specular.x * specular);
}

// Fog by horizontal distance: the terrain grid follows the eye horizontally, so its edge is
// always at the same horizontal distance, whatever the height of the eye.
vec3 apply_fog(vec3 color, vec3 world_pos) {
    float d = distance(world_pos.xz, camera_eye.xz);
    float x = sky_color.w * d;
    float fog = 1.0 - exp(-x * x);
    return mix(color, sky_color.rgb, clamp(fog, 0.0, 1.0));
}
