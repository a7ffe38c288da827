#version 410 core
#include "common.glsl"

// Points and lines of any colour (SEED.md 6 debug drawer).

uniform float point_size;

layout(location = 0) in vec3 position;
layout(location = 1) in vec4 color;

out vec4 d_color;

void main() {
    d_color = color;
    gl_Position = camera_view_projection * vec4(position, 1.0);
    gl_PointSize = point_size;
}
