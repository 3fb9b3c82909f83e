// Sun shadows (engine/render/shadows.py): include in both stages of a receiving program, compiled with the
// SHADOWS define (and SHADOW_SOFT for four taps) when the view has a shadow map.
// after lit.glsl (camera_pos):
//   vertex:   v_shadow = shadow_coord(world_position, world_normal);   (out vec4 v_shadow)
//   fragment: float lit = sun_visibility(v_shadow);                     1: in the sun, 0: in shadow
// The sun's diffuse and specular light are multiplied by it; ambient light is not.
#ifdef SHADOWS
uniform sampler2DShadow shadow_map;  // depth, compared (<=) and filtered bilinearly over 2 x 2 texels
uniform mat4 shadow_matrix;          // world -> (u, v, depth) in [0, 1] of the map
uniform vec3 shadow_params;          // x: normal offset (m); y: distance where shadows end (m); z: 1 / map size
// The look-up point moved along the normal by a texel or so (normal-offset bias): a receiver facing away from
// the sun does not compare against its own depth.  w: how far the shadow has faded out with the distance from
// the camera (over the last fifth of the shadow distance), linear enough to interpolate.
vec4 shadow_coord(vec3 world, vec3 n) {
    float d = length(world - camera_pos);
    float fade = clamp((d - 0.8 * shadow_params.y) / (0.2 * shadow_params.y), 0.0, 1.0);
    return vec4((shadow_matrix * vec4(world + normalize(n) * shadow_params.x, 1.0)).xyz, fade);
}
float sun_visibility(vec4 coord) {
    vec3 c = coord.xyz;
    if (c.x <= 0.0 || c.y <= 0.0 || c.x >= 1.0 || c.y >= 1.0 || c.z >= 1.0) return 1.0;
#ifdef SHADOW_SOFT
    float t = shadow_params.z;
    float v = 0.25 * (texture(shadow_map, c + vec3(-t, -t, 0.0)) + texture(shadow_map, c + vec3(t, -t, 0.0))
                    + texture(shadow_map, c + vec3(-t, t, 0.0)) + texture(shadow_map, c + vec3(t, t, 0.0)));
#else
    float v = texture(shadow_map, c);
#endif
    return mix(v, 1.0, coord.w);
}
#endif
