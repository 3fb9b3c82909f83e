#version 330
// PBVR ensemble pass (2.3, seeds/004): K random pseudo-particles around each real particle, drawn as opaque
// points.  One draw = one repeat r: every fragment gets the depth of this repeat's slab, so with the depth test
// GL_LESS a pixel is counted once per repeat (the colour is uniform, so which pseudo-particle wins a pixel does
// not change the image); occlusion by the scene is tested against the view's depth in the fragment shader.
uniform mat4 view_proj;
uniform int sub_particles;   // K
uniform int repeat_index;    // r in [0, R)
uniform int frame_seed;      // changes every frame: a new ensemble
uniform float radius;        // metres: pseudo-particles are uniform in a ball of this radius
uniform float slab_depth;    // NDC depth of this repeat's slab
uniform float point_size;    // pixels
in vec3 in_position;         // the real particle, world space
flat out float v_depth;      // window-space depth of the pseudo-particle

uvec3 pcg3d(uvec3 v) {      // Jarzynski & Olano 2020, "Hash Functions for GPU Rendering"
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    v ^= v >> 16u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    return v;
}

void main() {
    uint sample_id = uint(repeat_index * sub_particles + gl_InstanceID);
    uvec3 h = pcg3d(uvec3(uint(gl_VertexID), sample_id, uint(frame_seed)));
    vec3 u = vec3(h >> 8u) * (1.0 / 16777216.0);
    float z = 2.0 * u.x - 1.0;
    float phi = 6.28318530718 * u.y;
    float s = sqrt(max(0.0, 1.0 - z * z));
    vec3 offset = radius * pow(u.z, 1.0 / 3.0) * vec3(s * cos(phi), z, s * sin(phi));
    vec4 clip = view_proj * vec4(in_position + offset, 1.0);
    float ndc_z = clip.z / clip.w;
    v_depth = 0.5 * ndc_z + 0.5;
    if (clip.w <= 0.0 || ndc_z < -1.0 || ndc_z > 1.0) {
        gl_Position = vec4(2.0, 2.0, 2.0, 1.0);  // outside the near/far range: clipped away
    } else {
        gl_Position = vec4(clip.xy, slab_depth * clip.w, clip.w);
    }
    gl_PointSize = point_size;
}
