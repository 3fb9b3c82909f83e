#version 330
#include "lit.glsl"
#include "common.glsl"
#include "terrain_shadow.glsl"
#include "shadow.glsl"
// Level 4: one textured rectangle per cell, instanced. The rectangle faces azimuth i_face (turned by the 15°
// rule on the CPU) and shows cached view i_tiles.x (i_tiles.y is cross-faded in with weight i_blend when the
// blending option is on). It is drawn scaled about the eye so it sits in front of the cell's content while
// covering exactly the same pixels.
uniform mat4 view_proj;
uniform vec3 eye;
uniform int ortho;
uniform vec4 frame;        // half width, bottom, top, depth of the cached region
uniform float elevation;   // of the cached views
uniform vec4 atlas;        // columns, tile width, tile height, padding (texels)
uniform vec2 atlas_size;
uniform sampler2D bounds_tex;  // per tile: the part holding grass (u0, v0, u1, v1); the rectangle is trimmed to it
in vec3 i_centre;
in float i_face;
in vec2 i_tiles;
in float i_blend;
in float i_level;
in float i_relief;      // how far the cell's ground strays from the flat ground its images were baked on
in float i_turn;        // the cell's quarter turns (its layout turned into place: layout.place_field)
out vec2 v_uv_a;
out vec2 v_uv_b;
out float v_blend;
out float v_fog;        // fog factor (lit.glsl's fog) per corner: a rectangle spans little of the fog's range
flat out int v_level;
flat out vec2 v_turn;   // cosine and sine of the cell's turn: the atlas's normals are in its layout's frame
#ifdef BAND_DISTANCE
out vec3 v_world;       // the rectangle's point where the cell stands (before the scaling about the eye)
#endif
#ifdef TERRAIN_SHADOW
out float v_sun;        // the share of the sun the terrain leaves on the ground there (per corner, interpolated;
                        // the ground's, as the plants of levels 0-3 take it at their foot)
#endif
#if defined(SHADOWS) || defined(GRASS_DEPTH)
// Where the texel's grass stands (impostor.frag): the point of the cached view's orthographic camera at the
// texel's window depth (the atlas's depth image), in the rectangle's frame (the view turned to face as the
// rectangle is, so it matches what is drawn): v_grass + depth · v_depth_dir.
uniform vec2 bake_depth;  // the cached views' camera: its near plane's distance from the cell's centre, far - near
out vec3 v_grass;         // the point at window depth 0 (the near plane)
flat out vec3 v_depth_dir;
#endif
#ifdef GRASS_DEPTH
// GRASS_DEPTH: the fragment's depth is that point's (clip z and w linear in the depth: v_clip + depth ·
// v_clip_dir), moved towards the eye by the cell's relief and a quarter of a plant height (the images stand on
// flat ground; the terrain under the cell may rise by that much), instead of the rectangle's, which is pushed in
// front of the whole cell and so hides what stands inside it (a player walking through the grass).
uniform float depth_margin;
out vec2 v_clip;
flat out vec2 v_clip_dir;
#endif
vec2 tile_uv(float tile, vec2 local) {
    int t = int(tile + 0.5);
    int cols = int(atlas.x + 0.5);
    vec2 slot = vec2(float(t % cols), float(t / cols));
    vec2 origin = slot * (atlas.yz + 2.0 * atlas.w) + atlas.w;
    return (origin + local * atlas.yz) / atlas_size;
}
void main() {
    vec4 bounds = fetch(bounds_tex, int(i_tiles.x + 0.5));
    if (i_blend > 0.0) {
        vec4 other = fetch(bounds_tex, int(i_tiles.y + 0.5));
        bounds = vec4(min(bounds.xy, other.xy), max(bounds.zw, other.zw));
    }
    vec2 corner = mix(bounds.xy, bounds.zw, vec2(float(gl_VertexID & 1), float(gl_VertexID >> 1)));
    vec3 right, up, normal;
    impostor_basis(i_face, elevation, right, up, normal);
    vec3 world = i_centre + ((corner.x * 2.0 - 1.0) * frame.x) * right + mix(frame.y, frame.z, corner.y) * up;
#if defined(SHADOWS) || defined(GRASS_DEPTH)
    // impostor.bake_view_proj: an orthographic camera on the normal looking down -normal (bake_depth_range)
    v_grass = world + normal * bake_depth.x;
    v_depth_dir = -normal * bake_depth.y;
#endif
#ifdef GRASS_DEPTH
    vec3 toward_eye = ortho == 0 ? normalize(eye - world) : normal;
    v_clip = (view_proj * vec4(v_grass + toward_eye * (i_relief + depth_margin), 1.0)).zw;
    v_clip_dir = (view_proj * vec4(v_depth_dir, 0.0)).zw;
#endif
    v_fog = clamp(1.0 - exp(-length(camera_pos - world) * fog_density), 0.0, 1.0);
#ifdef BAND_DISTANCE
    v_world = world;
#endif
#ifdef TERRAIN_SHADOW
    v_sun = terrain_sun_ground(world);
#endif
    if (ortho == 0) {
        float d = length(i_centre - eye);
        world = eye + (world - eye) * max(0.05, (d - frame.w) / max(d, 1e-4));
    } else {
        world += normal * frame.w;
    }
    int turn = int(i_turn + 0.5) & 3;  // quarter turns: exact cosines and sines
    v_turn = vec2(turn == 0 ? 1.0 : (turn == 2 ? -1.0 : 0.0), turn == 1 ? 1.0 : (turn == 3 ? -1.0 : 0.0));
    v_uv_a = tile_uv(i_tiles.x, corner);
    v_uv_b = tile_uv(i_tiles.y, corner);
    v_blend = i_blend;
    v_level = int(i_level + 0.5);
    gl_Position = view_proj * vec4(world, 1.0);
}
