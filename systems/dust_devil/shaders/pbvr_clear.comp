#version 430
// PBVR coverage clear for the compute scatter (2.3, seeds/004): zero the coverage words of the pixels the particle
// cloud can reach (its screen rectangle), word w of pixel (x, y) at (x, y + w * view_height).  A dispatch on the
// driver's worker threads instead of a scissored framebuffer clear, which a software rasteriser runs as a scene
// of its own.
layout(local_size_x = 8, local_size_y = 8) in;
layout(r32ui, binding = 0) uniform writeonly uimage2D coverage;
uniform ivec4 rect;          // x, y, width, height in pixels
uniform int view_height;
void main() {
    ivec2 q = ivec2(gl_GlobalInvocationID.xy);
    if (q.x < rect.z && q.y < rect.w) {
        imageStore(coverage, rect.xy + q + ivec2(0, int(gl_GlobalInvocationID.z) * view_height), uvec4(0u));
    }
}
