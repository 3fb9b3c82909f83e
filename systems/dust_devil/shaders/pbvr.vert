#version 330
// PBVR ensemble, slab form (2.3, seeds/004): the GL 3.3 path, used where the vertex stage cannot store to images.
// K random pseudo-particles around each real particle, drawn as opaque points.  One draw = one repeat r: every
// fragment gets the depth of this repeat's slab (w = 1, so the depth is exactly the slab's), so with the depth
// test GL_LESS a pixel is counted once per repeat (the colour is uniform, so which pseudo-particle wins a pixel
// does not change the image); occlusion by the scene is tested against the view's depth in the fragment shader.
uniform mat4 view_proj;
uniform int sub_particles;   // K
uniform int repeat_index;    // r in [0, R)
uniform uint frame_key;      // changes every frame: a new ensemble (pbvr_sample.glsl)
uniform float radius;        // metres: pseudo-particles are uniform in a ball of this radius
uniform float slab_depth;    // NDC depth of this repeat's slab
uniform float point_size;    // pixels
in vec3 in_position;         // the real particle, world space
flat out float v_depth;      // window-space depth of the pseudo-particle

#include "pbvr_sample.glsl"

void main() {
    int sample_id = repeat_index * sub_particles + gl_InstanceID;
    vec3 offset = radius * ball_offset(particle_key(gl_VertexID, frame_key), sample_id);
    vec4 clip = view_proj * vec4(in_position + offset, 1.0);
    float ndc_z = clip.z / clip.w;
    v_depth = 0.5 * ndc_z + 0.5;
    if (clip.w <= 0.0 || ndc_z < -1.0 || ndc_z > 1.0) {
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);  // outside the near/far range: clipped away
    } else {
        // w = 1: a point needs no perspective division, and z/w = slab_depth exactly (with w = clip.w the
        // division's rounding gave the same repeat slightly different depths, so a pixel could count twice)
        gl_Position = vec4(clip.xy / clip.w, slab_depth, 1.0);
    }
    gl_PointSize = point_size;
}
