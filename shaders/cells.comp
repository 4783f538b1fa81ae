// Duplex: one invocation per cell. Its visible splats (those preprocess kept) go to the front of its slot range in
// `vis` (in member order: the CPU orders them canonically, which changes only float rounding); a cell with at
// least one is projected (preprocess_cell) and flagged; atomics keep the visible cells' depth range.
#include "common.glsl"
#include "mathf.glsl"
#include "camera.glsl"
#include "preprocess.glsl"
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer CellGeom { vec4 cell_geom[]; };  // per cell: mean, scale, quat
layout(std430, binding = 1) readonly buffer Offsets { int cell_offsets[]; };  // M + 1
layout(std430, binding = 2) readonly buffer Members { int cell_members[]; };
layout(std430, binding = 3) readonly buffer Rects { ivec4 rects[]; };  // splat rects, empty when culled
layout(std430, binding = 4) writeonly buffer Vis { uint vis[]; };
layout(std430, binding = 5) writeonly buffer CellOut { vec4 cell_out[]; };  // xy, depth, visible member count
layout(std430, binding = 6) writeonly buffer CellRects { ivec4 cell_rects[]; };
layout(std430, binding = 7) writeonly buffer Flags { uint flags[]; };
layout(std430, binding = 8) buffer Totals { uint totals[]; };

uniform uint num_cells;
uniform ivec2 grid;
uniform float cam_R[9];
uniform float cam_t[3];
uniform vec4 cam_f;
uniform ivec2 cam_size;
uniform float cam_near;
uniform int cam_projection;  // PERSPECTIVE or ORTHOGRAPHIC

float load_sh(uint splat, int coeff, int channel) { return 0.0; }
float load_weight_sh(uint splat, int coeff) { return 0.0; }

void main() {
    const uint c = group_index() * 256u + gl_LocalInvocationID.x;
    if (c >= num_cells) return;
    const int begin = cell_offsets[c], end = cell_offsets[c + 1u];
    uint count = 0u;
    for (int j = begin; j < end; ++j) {
        const int s = cell_members[j];
        const ivec4 r = rects[s];
        if (r.z > r.x) vis[uint(begin) + count++] = uint(s);
    }
    flags[c] = 0u;
    cell_rects[c] = ivec4(0);
    if (count == 0u) return;
    const CameraParams cam =
        make_camera(cam_R, cam_t, cam_f.x, cam_f.y, cam_f.z, cam_f.w, cam_size.x, cam_size.y, cam_near, cam_projection);
    const CellIn in_ = CellIn(cell_geom[CELL_GEOM_VEC4S * c].xyz, cell_geom[CELL_GEOM_VEC4S * c + 1u].xyz,
                              cell_geom[CELL_GEOM_VEC4S * c + 2u]);
    Cell2D cell;
    TileRect r;
    if (!preprocess_cell(in_, cam, grid.x, grid.y, cell, r)) return;
    flags[c] = 1u;
    cell_rects[c] = ivec4(r.x0, r.y0, r.x1, r.y1);
    cell_out[c] = vec4(cell.xy, cell.depth, uintBitsToFloat(count));
    const uint area = uint((r.x1 - r.x0) * (r.y1 - r.y0));
    atomicAdd(totals[TOTAL_CELL_PAIRS], area);
    atomicAdd(totals[TOTAL_CELL_SPLATS], count);
    const uint bits = floatBitsToUint(cell.depth);
    atomicMin(totals[TOTAL_CELL_DEPTH_MIN], bits);
    atomicMax(totals[TOTAL_CELL_DEPTH_MAX], bits);
}
