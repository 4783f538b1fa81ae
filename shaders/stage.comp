// The per-camera stage of every splat (stage_splat): stored as pack_stage records with their kept flag, then read by
// every mode's finish (preprocess.comp) while the camera, the scene and the SH degree hold (glsl/renderer.py).
#include "common.glsl"
#include "mathf.glsl"
#include "camera.glsl"
#include "preprocess.glsl"
#include "kernel.glsl"

layout(local_size_x = 256) in;
layout(std430, binding = 0) readonly buffer Geom { vec4 geom[]; };  // per splat: mean+opacity, scale+filter, quat
layout(std430, binding = 1) readonly buffer Sh { float sh_data[]; };  // per splat: K x 3 floats
layout(std430, binding = 2) writeonly buffer Stage { vec4 stage[]; };
#define LOD_ROWS_BINDING 3
#include "lod_rows.glsl"

uniform uint num_splats;
uniform int sh_k;  // SH coefficients per channel stored in the scene
uniform int sh_deg;  // degree evaluated
uniform ivec2 grid;
uniform float reach;  // the largest diagonal a mode's 2D filter adds (stage_on_screen)
uniform int rules;  // the presets' stage rules (stage_rules)
uniform float cam_R[9];
uniform float cam_t[3];
uniform vec4 cam_f;  // fx, fy, cx, cy
uniform ivec2 cam_size;
uniform float cam_near;
uniform int cam_projection;  // PERSPECTIVE or ORTHOGRAPHIC

float load_sh(uint splat, int coeff, int channel) {
    return sh_data[splat_row(splat) * uint(3 * sh_k) + uint(coeff * 3 + channel)];
}

float load_weight_sh(uint splat, int coeff) { return 0.0; }  // the finish's (view weights)

void main() {
    const uint i = group_index() * 256u + gl_LocalInvocationID.x;
    if (i >= num_splats) return;
    const CameraParams cam =
        make_camera(cam_R, cam_t, cam_f.x, cam_f.y, cam_f.z, cam_f.w, cam_size.x, cam_size.y, cam_near, cam_projection);
    const uint row = splat_row(i);
    const vec4 g0 = geom[GEOM_VEC4S * row], g1 = geom[GEOM_VEC4S * row + 1u], g2 = geom[GEOM_VEC4S * row + 2u];
    precise const float opacity = g0.w * splat_weight(i);  // in float32 as the gathered cut's (lod gather)
    const SplatIn in_ = SplatIn(g0.xyz, g1.xyz, g2, opacity, i, g1.w, false, 0, -1);
    StageSplat st = StageSplat(vec2(0.0), 0.0, 0.0, vec3(0.0), vec3(0.0));
    const bool kept = stage_splat(in_, sh_deg, rules, cam, grid.x, grid.y, reach, st);
    vec4 p0, p1, p2;
    pack_stage(st, kept, p0, p1, p2);
    stage[STAGE_VEC4S * i] = p0;
    stage[STAGE_VEC4S * i + 1u] = p1;
    stage[STAGE_VEC4S * i + 2u] = p2;
}
