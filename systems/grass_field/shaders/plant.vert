#version 330
#include "common.glsl"
// Levels 0-3 (table 1), instanced: one instance per plant listed for this level.
// Instance i draws plant plant_list[list_offset + i]; the indexed vertex comes from the plant's variant:
// mesh_tex[variant * mesh_verts + gl_VertexID] (2 texels per vertex).
uniform mat4 view_proj;
uniform sampler2D mesh_tex;
uniform int mesh_verts;
uniform sampler2D plant_tex;   // per plant: (x, y, z, yaw), (scale, variant, tint, 0)
uniform isampler2D plant_list;
uniform int list_offset;
uniform vec3 stem_color;
uniform vec3 leaf_base_color;
uniform vec3 leaf_tip_color;
out vec3 v_pos;
out vec3 v_normal;
out vec3 v_albedo;
flat out float v_kind;
void main() {
    int plant = fetch_int(plant_list, list_offset + gl_InstanceID);
    vec4 p0 = fetch(plant_tex, 2 * plant);
    vec4 p1 = fetch(plant_tex, 2 * plant + 1);
    int vid = int(p1.y + 0.5) * mesh_verts + gl_VertexID;
    vec4 a = fetch(mesh_tex, 2 * vid);
    vec4 b = fetch(mesh_tex, 2 * vid + 1);
    vec3 world = rotate_xz(a.xyz * p1.x, p0.w) + p0.xyz;
    v_pos = world;
    v_normal = rotate_xz(b.xyz, p0.w);
    v_kind = b.w;
    vec3 albedo = (b.w > 0.5 && b.w < 1.5) ? mix(leaf_base_color, leaf_tip_color, a.w) : stem_color;
    v_albedo = albedo * (1.0 + p1.z);
    gl_Position = view_proj * vec4(world, 1.0);
}
