#version 330
// Isosurface vertices of the display-grid density (seeds/002 §3.5) and the sphere obstacle.
// The ramp coordinate is computed per vertex, as in the paper: c = (-v·g + 1) / 2 with v the unit line of sight
// (eye -> vertex) and g the unit density gradient (g = -n, n the outward normal from marching cubes).
uniform mat4 view_proj;
uniform mat4 model;
uniform vec3 camera_pos;
uniform vec3 camera_forward;
uniform bool ortho;
in vec3 in_position;
in vec3 in_normal;
out vec3 v_world;
out vec3 v_normal;
out float v_ramp;
void main() {
    vec4 world = model * vec4(in_position, 1.0);
    v_world = world.xyz;
    v_normal = mat3(model) * in_normal;  // model is rigid (rotation + translation)
    vec3 sight = ortho ? camera_forward : normalize(world.xyz - camera_pos);
    float len = length(v_normal);
    vec3 g = len > 0.0 ? -v_normal / len : vec3(0.0);
    v_ramp = clamp((1.0 - dot(sight, g)) * 0.5, 0.0, 1.0);
    gl_Position = view_proj * world;
}
