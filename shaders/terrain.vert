#version 410 core
#include "common.glsl"
#include "terrain_common.glsl"

// One corner of a flat patch, in patch units of the grid; the grid follows the camera in whole
// patches, so every corner keeps the same world position while it is on screen.
layout(location = 0) in vec2 corner;

out vec2 v_xz;

void main() {
    v_xz = terrain_grid.xy + corner * terrain_grid.z;
}
