#version 410 core

in vec4 d_color;

out vec4 frag_color;

void main() {
    frag_color = d_color;
}
