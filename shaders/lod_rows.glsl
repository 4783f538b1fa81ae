// A level-of-detail cut drawn in place (glsl/renderer.py): splat i of the frame is the uploaded row lod_rows[i].x (the
// scene's splats, then its hierarchy's interior nodes) with its opacity times the cut's weight, the float bits
// lod_rows[i].y; without one (lod_in_place 0) splat i is row i at weight 1. The includer defines LOD_ROWS_BINDING.
layout(std430, binding = LOD_ROWS_BINDING) readonly buffer LodRows { uvec2 lod_rows[]; };

uniform int lod_in_place;

uint splat_row(uint i) { return lod_in_place != 0 ? lod_rows[i].x : i; }

float splat_weight(uint i) { return lod_in_place != 0 ? uintBitsToFloat(lod_rows[i].y) : 1.0; }
