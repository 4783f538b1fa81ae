// The storage interface between the glsl backend's driver (gbviewer/render/glsl/) and its kernels (*.comp): the
// slots of the per-frame counter buffer, the record sizes of the storage buffers and the components of the `oit`
// uniform. This file is the one definition: the kernels include it (through kernel.glsl), and
// gbviewer/render/glsl/interface.py reads it when imported, so it holds only `const int|uint NAME = VALUE;` lines
// and comments. tests/render/test_glsl_interface.py checks it against the C++ structs (sizeof / offsetof).

// Slots of the counter buffer `totals` (uint each), cleared per frame and read back once.
const int TOTAL_VISIBLE = 0;  // splats that survive preprocess (written by the scan of their flags)
const int TOTAL_PAIRS = 1;  // tile-splat pairs (sum of the tile rectangles' areas)
const int TOTAL_DEPTH_MIN = 2;  // min / max bits of the visible depths (positive floats order as uints);
const int TOTAL_DEPTH_MAX = 3;  // the min slots start at 0xFFFFFFFF, every other slot at 0
const int TOTAL_OVERFLOW = 4;  // set when TOTAL_PAIRS wrapped past 2^32
const int TOTAL_MAX_LIST = 5;  // longest tile list (list_max.comp)
const int TOTAL_CELL_PAIRS = 6;  // duplex: tile-cell pairs
const int TOTAL_CELL_DEPTH_MIN = 7;  // duplex: min / max bits of the visible cells' depths
const int TOTAL_CELL_DEPTH_MAX = 8;
const int TOTAL_CELLS = 9;  // duplex: visible cells (scan of their flags)
const int TOTAL_EXPANDED = 10;  // duplex: entries of the expanded tile lists (splats)
const int TOTAL_CELL_SPLATS = 11;  // duplex: visible splats of the visible cells
const int TOTALS_SLOTS = 16;  // size of the buffer in slots
const int NO_TOTAL = -1;  // scan_blocks.comp's total_slot when the total goes nowhere

// Records of the storage buffers, in vec4 (16 bytes) or 32-bit words, indexed like the scene or the tiles.
const uint SPLAT_VEC4S = 4u;  // Splat2D as pack_splat stores it (kernel.glsl)
const uint STAGE_VEC4S = 3u;  // StageSplat as pack_stage stores it (kernel.glsl), with its kept flag
const uint GEOM_VEC4S = 3u;  // splat geometry: mean + opacity, scale + 3D filter, unit quaternion (w, x, y, z)
const uint CELL_GEOM_VEC4S = 3u;  // duplex cell ellipsoid: mean + 0, scale + 0, quaternion
const uint CELL_OUT_VEC4S = 1u;  // projected cell: xy, depth, visible member count (uint bits)
const uint RECT_WORDS = 4u;  // TileRect: ivec4(x0, y0, x1, y1), empty when x1 <= x0
const uint RANGE_WORDS = 2u;  // a tile's [start, end) in its list: uvec2
const uint WINDOW_WORDS = 2u;  // gaussian_blending's final window sides per output pixel: vec2
const uint BLEND_STATE_VEC4S = 3u;  // blend.comp's per-invocation state between dispatches: C, T; xy, wh; evals, done
const uint BLEND_ACCUM_VEC4S = 2u;  // blend.comp's per-invocation box sum: rgba; window sum, evals sum
const uint RAY_VEC4S = 4u;  // RaySplat (eval3d, stopthepop) as pack_ray stores it (ray3d.glsl)

// OitParams' fields in order: 0..3 the components of the `oit` vec4 uniform (depth_correct as 0.0 or 1.0), 4..7
// those of preprocess.comp's `view_filter` vec4 uniform less 4 (the scalar mode's filter, compensate as 0.0 or 1.0),
// 8..10 those of its `view_rules` vec3 uniform less 8 (the presets' rules, dc_clamp and sort_radial as 0.0 or 1.0).
const int OIT_SIGMA = 0;
const int OIT_WEIGHT_BACKGROUND = 1;
const int OIT_ET_GRADE = 2;
const int OIT_DEPTH_CORRECT = 3;
const int OIT_DILATION = 4;
const int OIT_PRE_DILATION = 5;
const int OIT_CULL_LAMBDA = 6;
const int OIT_COMPENSATE = 7;
const int OIT_DC_CLAMP = 8;
const int OIT_SUPPORT = 9;
const int OIT_SORT_RADIAL = 10;
