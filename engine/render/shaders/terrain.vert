#version 330
uniform mat4 view_proj;
uniform mat4 model;
in vec3 in_position;
in vec3 in_normal;
out vec3 v_pos;
out vec3 v_normal;
out float v_height;
void main() {
    vec4 world = model * vec4(in_position, 1.0);
    v_pos = world.xyz;
    v_normal = mat3(model) * in_normal;
    v_height = in_position.y;
    gl_Position = view_proj * world;
}
