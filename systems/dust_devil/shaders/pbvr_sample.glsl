// The random pseudo-particles of PBVR (2.3, seeds/004), shared by the scatter (GL 4.2/4.3) and the slab (GL 3.3)
// shaders.  Sample `sample_id` = r * K + k of real particle `particle` is an offset from a table of BALL_OFFSETS
// points drawn once, independently and uniformly in the unit ball, from the engine's seeded random streams
// (render.ball_offsets): entry (key + sample_id) mod BALL_OFFSETS, key = a hash of the particle and the frame.
// A particle's R x K <= 1024 samples are thus distinct table entries (independent, each uniform in the ball),
// and every frame hashes new keys (a new ensemble).  One hash per particle and one fetch per sample: no pow,
// sin or cos per pseudo-particle.  render.py re-implements this in numpy (tests compare).
#define BALL_OFFSETS 1024    // a power of two; 1024 vec4 = 16 KiB, the smallest uniform block GL guarantees

layout(std140) uniform BallOffsets {
    vec4 ball_offsets[BALL_OFFSETS];  // xyz: a point uniform in the unit ball; w unused
};

uint pcg_hash(uint v) {     // Jarzynski & Olano 2020, "Hash Functions for GPU Rendering" (PCG, one word)
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

// The table index of a particle's sample 0 this frame (frame_key: a hash of the tick drawn and the frames drawn at it
// before, set by render.py).
uint particle_key(int particle, uint frame_key) {
    return pcg_hash(uint(particle) + frame_key);
}

// Sample sample_id's offset in the unit ball (times the ball's radius: metres).
vec3 ball_offset(uint key, int sample_id) {
    return ball_offsets[(key + uint(sample_id)) & uint(BALL_OFFSETS - 1)].xyz;
}
