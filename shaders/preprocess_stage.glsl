// GLSL port of native/include/gbv/preprocess_stage.h (the per-camera stage of the preprocess), function by function
// with the same names; included by preprocess.glsl after the SH functions (sh.h), whose conventions it follows.

// port of preprocess_stage.h: covariance_3d
void covariance_3d(vec4 q, vec3 s, precise out float cov[6]) {
    const float r = q[0], x = q[1], y = q[2], z = q[3];
    precise const float R[9] = float[](1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - r * z), 2.0 * (x * z + r * y),
                                       2.0 * (x * y + r * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - r * x),
                                       2.0 * (x * z - r * y), 2.0 * (y * z + r * x), 1.0 - 2.0 * (x * x + y * y));
    precise float M[9];  // M = R S
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) M[i * 3 + j] = R[i * 3 + j] * s[j];
    cov[0] = M[0] * M[0] + M[1] * M[1] + M[2] * M[2];
    cov[1] = M[0] * M[3] + M[1] * M[4] + M[2] * M[5];
    cov[2] = M[0] * M[6] + M[1] * M[7] + M[2] * M[8];
    cov[3] = M[3] * M[3] + M[4] * M[4] + M[5] * M[5];
    cov[4] = M[3] * M[6] + M[4] * M[7] + M[5] * M[8];
    cov[5] = M[6] * M[6] + M[7] * M[7] + M[8] * M[8];
}

// port of preprocess_stage.h: project_covariance
void project_covariance(CameraParams cam, float cov3[6], vec3 pv, precise out vec3 result) {
    precise float j00 = cam.fx, j02 = 0.0, j11 = cam.fy, j12 = 0.0;
    if (cam.projection != ORTHOGRAPHIC) {
        const float tz = pv[2];
        precise const float tx = clampf(pv[0] / tz, -cam.lim_x_neg, cam.lim_x_pos) * tz;
        precise const float ty = clampf(pv[1] / tz, -cam.lim_y_neg, cam.lim_y_pos) * tz;
        j00 = cam.fx / tz;
        j02 = -cam.fx * tx / (tz * tz);
        j11 = cam.fy / tz;
        j12 = -cam.fy * ty / (tz * tz);
    }
    // T = J W (2x3), W = cam.R
    precise float T[6];
    for (int c = 0; c < 3; ++c) {
        T[c] = j00 * cam.R[c] + j02 * cam.R[6 + c];
        T[3 + c] = j11 * cam.R[3 + c] + j12 * cam.R[6 + c];
    }
    const float S[9] = float[](cov3[0], cov3[1], cov3[2], cov3[1], cov3[3], cov3[4], cov3[2], cov3[4], cov3[5]);
    precise float TS[6];
    for (int r = 0; r < 2; ++r)
        for (int c = 0; c < 3; ++c) TS[r * 3 + c] = T[r * 3] * S[c] + T[r * 3 + 1] * S[3 + c] + T[r * 3 + 2] * S[6 + c];
    result[0] = TS[0] * T[0] + TS[1] * T[1] + TS[2] * T[2];
    result[1] = TS[0] * T[3] + TS[1] * T[4] + TS[2] * T[5];
    result[2] = TS[3] * T[3] + TS[4] * T[4] + TS[5] * T[5];
}

// port of preprocess_stage.h: SplatIn (`index` locates its SH coefficients)
struct SplatIn {
    vec3 mean;
    vec3 scale;
    vec4 quat;  // (w, x, y, z), unit
    float opacity;
    uint index;
    float filter_3d;  // 0 when the scene has none
    bool has_weight;  // the scene has view-weight SH (C++: weight_sh != null)
    int weight_deg;
    int cell;  // the splat's cell (duplex), -1 when none
};

// port of preprocess_stage.h: view_point
bool view_point(CameraParams cam, vec3 m, precise out vec3 pv) {
    for (int i = 0; i < 3; ++i)
        pv[i] = cam.R[i * 3] * m[0] + cam.R[i * 3 + 1] * m[1] + cam.R[i * 3 + 2] * m[2] + cam.t[i];
    return pv[2] > cam.near_plane;
}

// port of preprocess_stage.h: view_direction
void view_direction(CameraParams cam, vec3 m, precise out vec3 dir) {
    dir = cam.projection == ORTHOGRAPHIC ? vec3(cam.R[6], cam.R[7], cam.R[8])
                                         : vec3(m[0] - cam.campos[0], m[1] - cam.campos[1], m[2] - cam.campos[2]);
    precise const float dn = sqrt(dir.x * dir.x + dir.y * dir.y + dir.z * dir.z);
    dir = dn > 0.0 ? vec3(dir.x / dn, dir.y / dn, dir.z / dn) : vec3(0.0, 0.0, 1.0);
}

// port of preprocess_stage.h: screen_position
void screen_position(CameraParams cam, vec3 pv, precise out vec2 xy) {
    if (cam.projection == ORTHOGRAPHIC)
        xy = vec2(cam.fx * pv[0] + cam.cx, cam.fy * pv[1] + cam.cy);
    else
        xy = vec2(cam.fx * pv[0] / pv[2] + cam.cx, cam.fy * pv[1] / pv[2] + cam.cy);
}

// port of preprocess_stage.h: StageSplat (stored by pack_stage, kernel.glsl)
struct StageSplat {
    vec2 xy;
    float depth;
    float opacity;
    vec3 cov;
    vec3 color;
};

// port of preprocess_stage.h: STAGE_DC_CLAMP, STAGE_RADIAL
const int STAGE_DC_CLAMP = 1;
const int STAGE_RADIAL = 2;

// port of preprocess_stage.h: filter_3d_scales (the Mip-Splatting 3D filter: scales grow, opacity compensates)
void filter_3d_scales(SplatIn in_, precise out vec3 s, precise inout float opacity) {
    if (in_.filter_3d > 0.0) {
        precise const float f2 = in_.filter_3d * in_.filter_3d;
        precise float ratio = 1.0;
        for (int i = 0; i < 3; ++i) {
            precise const float s2 = in_.scale[i] * in_.scale[i];
            s[i] = sqrt(s2 + f2);
            ratio *= s2 / (s2 + f2);
        }
        opacity *= sqrt(ratio);
    } else {
        s = in_.scale;
    }
}

// port of preprocess_stage.h: preprocess_stage (all but the colour; false behind the near plane)
bool preprocess_stage(SplatIn in_, CameraParams cam, int rules, out StageSplat st) {
    precise vec3 pv;
    if (!view_point(cam, in_.mean, pv)) return false;
    precise vec3 s;
    precise float opacity = in_.opacity;
    filter_3d_scales(in_, s, opacity);
    precise float cov3[6];
    precise vec3 cov;
    covariance_3d(in_.quat, s, cov3);
    project_covariance(cam, cov3, pv, cov);
    precise vec2 xy;
    screen_position(cam, pv, xy);
    st.xy = xy;
    st.depth = pv[2];
    if ((rules & STAGE_RADIAL) != 0 && cam.projection != ORTHOGRAPHIC) {
        precise const float d2 = pv[0] * pv[0] + pv[1] * pv[1] + pv[2] * pv[2];
        st.depth = sqrt(d2);
    }
    st.opacity = opacity;
    st.cov = cov;
    st.color = vec3(0.0);
    return true;
}

// port of preprocess_stage.h: stage_color
void stage_color(SplatIn in_, int sh_deg, int rules, CameraParams cam, out vec3 color) {
    precise vec3 dir;
    view_direction(cam, in_.mean, dir);
    sh_to_rgb(in_.index, sh_deg, dir, (rules & STAGE_DC_CLAMP) != 0, color);
}

// port of preprocess_stage.h: stage_on_screen
bool stage_on_screen(StageSplat st, int grid_x, int grid_y, float reach) {
    precise const float grow = 2.0 * reach + 0.4;
    precise const float h = 3.34 * sqrt(st.cov[0] + st.cov[2] + grow) + 2.0;
    const bool off = st.xy.x + h < 0.0 || st.xy.x - h > float(TILE * grid_x) + 1.0 || st.xy.y + h < 0.0 ||
                     st.xy.y - h > float(TILE * grid_y) + 1.0;
    return !off;
}

// The per-camera stage buffer's records (STAGE_VEC4S vec4 per splat, interface.glsl; not a port): vec4 0: xy,
// depth, opacity; 1: cov, kept (1.0: in front of the near plane and on screen in some mode, else 0.0);
// 2: color, 0.
void pack_stage(StageSplat s, bool kept, out vec4 p0, out vec4 p1, out vec4 p2) {
    p0 = vec4(s.xy, s.depth, s.opacity);
    p1 = vec4(s.cov, kept ? 1.0 : 0.0);
    p2 = vec4(s.color, 0.0);
}

StageSplat unpack_stage(vec4 p0, vec4 p1, vec4 p2, out bool kept) {
    kept = p1.w != 0.0;
    return StageSplat(p0.xy, p0.z, p0.w, p1.xyz, p2.xyz);
}
