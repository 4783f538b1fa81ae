#include "common.glsl"
#include "interface.glsl"

// Helpers shared by the compute kernels (*.comp): flat work-group index of a 2D dispatch, and the storage layout
// of Splat2D in the per-frame splat buffer (SPLAT_VEC4S vec4 per splat, indexed like the scene; StageSplat's is
// preprocess_stage.glsl's pack_stage). The counter slots
// and record sizes are interface.glsl's.

// The driver spreads large 1D dispatches over x and y (at most 65535 groups per axis); kernels that see an index
// past their work return before any barrier, for the whole group at once.
uint group_index() { return gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x; }

// vec4 0: xy, depth, opacity; 1: conic, sigma1; 2: color, sigma2; 3: v1, log_min_alpha, radius. inv_sigma1/2 are
// not stored (64 bytes per splat instead of 80): unpacking recomputes them with the same division as preprocess. `cell` and `id` are not stored either: duplex reads the cell from the scene's per-splat cell buffer,
// blend.comp sets the id from the list entry (unpack gives -1 for both).
void pack_splat(Splat2D s, out vec4 p0, out vec4 p1, out vec4 p2, out vec4 p3) {
    p0 = vec4(s.xy, s.depth, s.opacity);
    p1 = vec4(s.conic, s.sigma1);
    p2 = vec4(s.color, s.sigma2);
    p3 = vec4(s.v1, s.log_min_alpha, s.radius);
}

Splat2D unpack_splat(vec4 p0, vec4 p1, vec4 p2, vec4 p3) {
    Splat2D s;
    s.xy = p0.xy;
    s.depth = p0.z;
    s.opacity = p0.w;
    s.conic = p1.xyz;
    s.sigma1 = p1.w;
    s.color = p2.xyz;
    s.sigma2 = p2.w;
    s.inv_sigma1 = 1.0 / s.sigma1;
    s.inv_sigma2 = 1.0 / s.sigma2;
    s.v1 = p3.xy;
    s.log_min_alpha = p3.z;
    s.radius = p3.w;
    s.cell = -1;
    s.id = -1;  // blend.comp sets the splat's index
    return s;
}
