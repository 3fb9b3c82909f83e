// The terrain's shadow (engine/render/terrain_shadow.py): include in a receiving stage compiled with the
// TERRAIN_SHADOW define (without it terrain_sun is 1).  TerrainShadow.uniforms sets these.
//   float lit = terrain_sun(world_position);   1: the terrain leaves the sun, 0: it hides it
//   float lit = terrain_sun_ground(world_position);   the same on the ground straight below or above the point
//                                                     (what stands on the ground and is drawn as one image)
// Multiply the sun's diffuse and specular light by it, as with shadow.glsl's sun_visibility; not the ambient.
#ifdef TERRAIN_SHADOW
uniform sampler2D terrain_shadow;     // rg32f, one texel per grid point: r the height below which the sun is
                                      // hidden, g the sun's share on the ground there
uniform mat4 terrain_shadow_matrix;   // world -> the terrain's local frame
uniform vec4 terrain_shadow_uv;       // local (x, z) -> texture (u, v): xy scale, zw offset
uniform vec2 terrain_shadow_params;   // x: 1 / penumbra height (local units); y: the value beside the terrain
// The point in the terrain's frame and its texture coordinates; false beside the terrain (uv outside [0, 1]).
bool terrain_shadow_at(vec3 world, out vec3 p, out vec2 uv) {
    p = (terrain_shadow_matrix * vec4(world, 1.0)).xyz;
    uv = p.xz * terrain_shadow_uv.xy + terrain_shadow_uv.zw;
    return uv.x >= 0.0 && uv.y >= 0.0 && uv.x <= 1.0 && uv.y <= 1.0;
}
float terrain_sun(vec3 world) {
    vec3 p;
    vec2 uv;
    if (!terrain_shadow_at(world, p, uv)) return terrain_shadow_params.y;
    return clamp((p.y - texture(terrain_shadow, uv).r) * terrain_shadow_params.x + 1.0, 0.0, 1.0);
}
float terrain_sun_ground(vec3 world) {
    vec3 p;
    vec2 uv;
    if (!terrain_shadow_at(world, p, uv)) return terrain_shadow_params.y;
    return texture(terrain_shadow, uv).g;
}
#else
float terrain_sun(vec3 world) { return 1.0; }
float terrain_sun_ground(vec3 world) { return 1.0; }
#endif
