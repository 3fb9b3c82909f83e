// The random pseudo-particles of PBVR (2.3, seeds/004), shared by the scatter (GL 4.2) and the slab (GL 3.3)
// shaders: sample `sample_id` = r * K + k of real particle `particle`, uniform in a ball of `radius`, hashed
// from particle, sample and frame, so both paths draw the same ensemble.

uvec3 pcg3d(uvec3 v) {      // Jarzynski & Olano 2020, "Hash Functions for GPU Rendering"
    v = v * 1664525u + 1013904223u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    v ^= v >> 16u;
    v.x += v.y * v.z; v.y += v.z * v.x; v.z += v.x * v.y;
    return v;
}

vec3 sub_particle_offset(int particle, int sample_id, int frame_seed, float radius) {
    uvec3 h = pcg3d(uvec3(uint(particle), uint(sample_id), uint(frame_seed)));
    vec3 u = vec3(h >> 8u) * (1.0 / 16777216.0);
    float z = 2.0 * u.x - 1.0;
    float phi = 6.28318530718 * u.y;
    float s = sqrt(max(0.0, 1.0 - z * z));
    return radius * pow(u.z, 1.0 / 3.0) * vec3(s * cos(phi), z, s * sin(phi));
}
