// The mode's finish of every splat's stored stage (finish_splat; the stage: stage.comp): store its Splat2D and tile
// rectangle, flag survivors, count tile-splat pairs and the depth range. The per-pixel sorted modes also store each
// splat's ray data (finish_ray_splat: after finish_splat for stopthepop, instead of it for eval3d).
#include "common.glsl"
#include "mathf.glsl"
#include "camera.glsl"
#include "preprocess.glsl"
#include "ray3d.glsl"
#include "ray3d_finish.glsl"
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Geom { vec4 geom[]; };  // per splat: mean+opacity, scale+filter, quat
layout(std430, binding = 1) readonly buffer Sh { float sh_data[]; };  // per splat: K x 3 floats
layout(std430, binding = 2) writeonly buffer Splats { vec4 splats[]; };
layout(std430, binding = 3) writeonly buffer Rects { ivec4 rects[]; };
layout(std430, binding = 4) writeonly buffer Flags { uint flags[]; };
layout(std430, binding = 5) buffer Totals { uint totals[]; };
layout(std430, binding = 6) readonly buffer WeightSh { float weight_sh[]; };  // per splat: weight_k floats
layout(std430, binding = 7) readonly buffer Stage { vec4 stage[]; };  // per splat: pack_stage's record
layout(std430, binding = 8) writeonly buffer Planes { vec4 planes[]; };  // stochastic_popfree: depth plane per splat
layout(std430, binding = 9) writeonly buffer Rays { vec4 rays[]; };  // eval3d, stopthepop: per splat, pack_ray's
#define LOD_ROWS_BINDING 10
#include "lod_rows.glsl"

uniform uint num_splats;
uniform int sh_k;  // SH coefficients per channel stored in the scene
uniform int sh_deg;  // degree evaluated
uniform int mode;
uniform ivec2 grid;
uniform float cam_R[9];
uniform float cam_t[3];
uniform vec4 cam_f;  // fx, fy, cx, cy
uniform ivec2 cam_size;
uniform float cam_near;
uniform int cam_projection;  // PERSPECTIVE or ORTHOGRAPHIC
uniform int weight_k;  // view-weight SH coefficients per splat, 0: none (v = 1)
uniform vec4 oit;  // OitParams (wsr, duplex): components OIT_* (interface.glsl)
uniform vec4 view_filter;  // OitParams' scalar filter: components OIT_* - 4 (interface.glsl)
uniform vec3 view_rules;  // OitParams' preset rules: components OIT_* - 8 (interface.glsl)

float load_sh(uint splat, int coeff, int channel) {
    return sh_data[splat_row(splat) * uint(3 * sh_k) + uint(coeff * 3 + channel)];
}

float load_weight_sh(uint splat, int coeff) { return weight_sh[splat * uint(weight_k) + uint(coeff)]; }

void main() {
    const uint i = group_index() * 256u + gl_LocalInvocationID.x;
    if (i >= num_splats) return;
    const CameraParams cam =
        make_camera(cam_R, cam_t, cam_f.x, cam_f.y, cam_f.z, cam_f.w, cam_size.x, cam_size.y, cam_near, cam_projection);
    const uint row = splat_row(i);
    const vec4 g0 = geom[GEOM_VEC4S * row], g1 = geom[GEOM_VEC4S * row + 1u], g2 = geom[GEOM_VEC4S * row + 2u];
    precise const float opacity = g0.w * splat_weight(i);  // in float32 as the gathered cut's (lod gather)
    const SplatIn in_ = SplatIn(g0.xyz, g1.xyz, g2, opacity, i, g1.w, weight_k > 0, sh_degree_for_coeffs(weight_k), -1);
    const OitParams params =
        OitParams(oit[OIT_SIGMA], oit[OIT_WEIGHT_BACKGROUND], oit[OIT_ET_GRADE], int(oit[OIT_DEPTH_CORRECT]),
                  view_filter[OIT_DILATION - 4], view_filter[OIT_PRE_DILATION - 4], view_filter[OIT_CULL_LAMBDA - 4],
                  int(view_filter[OIT_COMPENSATE - 4]), int(view_rules[OIT_DC_CLAMP - 8]), view_rules[OIT_SUPPORT - 8],
                  int(view_rules[OIT_SORT_RADIAL - 8]));
    bool kept;
    const StageSplat st =
        unpack_stage(stage[STAGE_VEC4S * i], stage[STAGE_VEC4S * i + 1u], stage[STAGE_VEC4S * i + 2u], kept);
    Splat2D s;
    TileRect r;
    bool valid = kept && (mode == EVAL3D || finish_splat(in_, st, sh_deg, cam, mode, params, grid.x, grid.y, s, r));
    if (valid && per_pixel_sorted(mode)) {
        RaySplat ray;
        valid = finish_ray_splat(in_, st, cam, mode, grid.x, grid.y, s, r, ray);
        vec4 q0, q1, q2, q3;
        pack_ray(ray, q0, q1, q2, q3);
        rays[RAY_VEC4S * i] = q0;
        rays[RAY_VEC4S * i + 1u] = q1;
        rays[RAY_VEC4S * i + 2u] = q2;
        rays[RAY_VEC4S * i + 3u] = q3;
    }
    flags[i] = valid ? 1u : 0u;
    if (!valid) {
        rects[i] = ivec4(0);
        return;
    }
    rects[i] = ivec4(r.x0, r.y0, r.x1, r.y1);
    vec4 p0, p1, p2, p3;
    pack_splat(s, p0, p1, p2, p3);
    splats[SPLAT_VEC4S * i] = p0;
    splats[SPLAT_VEC4S * i + 1u] = p1;
    splats[SPLAT_VEC4S * i + 2u] = p2;
    splats[SPLAT_VEC4S * i + 3u] = p3;
    if (mode == STOCHASTIC_POPFREE) planes[i] = splat_popfree_plane(cam, in_);
    const uint area = uint((r.x1 - r.x0) * (r.y1 - r.y0));
    const uint before = atomicAdd(totals[TOTAL_PAIRS], area);
    if (before + area < before) atomicOr(totals[TOTAL_OVERFLOW], 1u);
    const uint bits = floatBitsToUint(s.depth);  // depth > near > 0
    atomicMin(totals[TOTAL_DEPTH_MIN], bits);
    atomicMax(totals[TOTAL_DEPTH_MAX], bits);
}
