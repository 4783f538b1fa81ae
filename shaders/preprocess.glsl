// GLSL port of the one-splat preprocess of native/include/gbv/preprocess.h, sh.h and footprint.h (and, included,
// preprocess_stage.glsl: preprocess_stage.h), function by function with the same names and constants; each function's C++ original (named in its comment) documents it, and
// the comments here say only where the port differs. Needs common.glsl, mathf.glsl and, from the including kernel,
// `float load_sh(uint splat, int coeff, int channel)` (the scene's SH, coefficient-major, DC first).
// Values whose C++ products go through mul_rn are `precise` here (function outputs, locals): no multiply-add
// contraction, so culling decisions and tile rectangles do not depend on the driver's choice to fuse (common.h).

const float SH_C0 = 0.28209479177387814;
const float SH_C1 = 0.4886025119029199;
// Scalars rather than arrays, as in sh.h (where nvcc needs them).
const float SH_C2_0 = 1.0925484305920792, SH_C2_1 = -1.0925484305920792, SH_C2_2 = 0.31539156525252005,
            SH_C2_3 = -1.0925484305920792, SH_C2_4 = 0.5462742152960396;
const float SH_C3_0 = -0.5900435899266435, SH_C3_1 = 2.890611442640554, SH_C3_2 = -0.4570457994644658,
            SH_C3_3 = 0.3731763325901154, SH_C3_4 = -0.4570457994644658, SH_C3_5 = 1.445305721320277,
            SH_C3_6 = -0.5900435899266435;

float load_sh(uint splat, int coeff, int channel);
float load_weight_sh(uint splat, int coeff);  // the scene's view-weight SH (wsr, duplex); only read when present

// port of sh.h: sh_basis
int sh_basis(int deg, vec3 dir, precise out float basis[16]) {
    const float x = dir.x, y = dir.y, z = dir.z;
    basis[0] = SH_C0;
    if (deg < 1) return 1;
    basis[1] = -SH_C1 * y;
    basis[2] = SH_C1 * z;
    basis[3] = -SH_C1 * x;
    if (deg < 2) return 4;
    precise const float xx = x * x, yy = y * y, zz = z * z, xy = x * y, yz = y * z, xz = x * z;
    basis[4] = SH_C2_0 * xy;
    basis[5] = SH_C2_1 * yz;
    basis[6] = SH_C2_2 * (2.0 * zz - xx - yy);
    basis[7] = SH_C2_3 * xz;
    basis[8] = SH_C2_4 * (xx - yy);
    if (deg < 3) return 9;
    basis[9] = SH_C3_0 * y * (3.0 * xx - yy);
    basis[10] = SH_C3_1 * xy * z;
    basis[11] = SH_C3_2 * y * (4.0 * zz - xx - yy);
    basis[12] = SH_C3_3 * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    basis[13] = SH_C3_4 * x * (4.0 * zz - xx - yy);
    basis[14] = SH_C3_5 * z * (xx - yy);
    basis[15] = SH_C3_6 * x * (xx - 3.0 * yy);
    return 16;
}

// port of sh.h: sh_to_rgb (`splat` selects the coefficients (C++: a pointer to them))
void sh_to_rgb(uint splat, int deg, vec3 dir, bool dc_clamp, out vec3 result) {
    float basis[16];
    const int k = sh_basis(deg, dir, basis);
    for (int c = 0; c < 3; ++c) {
        precise float v = 0.5 + basis[0] * load_sh(splat, 0, c);
        if (dc_clamp) v = min(max(v, 0.0), 1.0);
        for (int i = 1; i < k; ++i) v += basis[i] * load_sh(splat, i, c);
        result[c] = max(v, 0.0);
    }
}

// port of sh.h: sh_to_weight
float sh_to_weight(uint splat, int deg, vec3 dir) {
    float basis[16];
    const int k = sh_basis(deg, dir, basis);
    precise float v = 0.0;
    for (int i = 0; i < k; ++i) v += basis[i] * load_weight_sh(splat, i);
    return v;
}

#include "preprocess_stage.glsl"

// port of footprint.h: eigen_2d
void eigen_2d(float a, float b, float c, float det, out float sigma1, out float sigma2, out vec2 v1) {
    const float mid = 0.5 * (a + c);
    const float root = sqrt(max(0.0, mid * mid - det));
    const float l1 = mid + root;
    const float l2 = det / l1;
    sigma1 = sqrt(l1);
    sigma2 = sqrt(l2);
    const vec2 e1 = vec2(b, l1 - a), e2 = vec2(l1 - c, b);
    const float n1 = dot(e1, e1), n2 = dot(e2, e2);
    const vec2 e = n1 >= n2 ? e1 : e2;
    const float n = max(n1, n2);
    v1 = n > 1e-30 ? (1.0 / sqrt(n)) * e : vec2(1.0, 0.0);
}

// port of footprint.h: splat_radius
float splat_radius(float a, float c, float det, float sigmas) {
    precise const float mid = 0.5 * (a + c);
    precise const float lmax = mid + sqrt(max(0.1, mid * mid - det));
    return ceil(sigmas * sqrt(lmax));
}

// port of footprint.h: log_upper
float log_upper(float x) {
    int e;
    const float m = 2.0 * frexp(x, e);  // x = m 2^(e - 1)
    precise const float t = m - 1.0;
    precise const float t2 = t * t;
    precise const float v = float(e - 1) * 0.69314720 + t - 0.5 * t2 + (t2 * t) * 0.33333334;
    return v;
}

// port of footprint.h: cutoff_half_sides
vec2 cutoff_half_sides(int mode, vec3 cov, float det, float opacity, float min_alpha, float r) {
    if (mode == GAUSSIAN_BLENDING || mode == ANALYTIC) return vec2(r, r);
    precise const float r2 = 2.0 * log_upper(opacity / min_alpha) + 1e-6;
    precise const float mid = 0.5 * (cov[0] + cov[2]);
    precise const float l1 = mid + sqrt(max(0.0, mid * mid - det));
    precise const float grow = 1.00001 + 1e-6 * ((l1 * l1) / det);
    precise const float hx = ceil(sqrt(r2 * cov[0]) * grow + 0.02) + 1.0;
    precise const float hy = ceil(sqrt(r2 * cov[2]) * grow + 0.02) + 1.0;
    return vec2(minf(hx, r), minf(hy, r));
}

// port of footprint.h: tile_rect
TileRect tile_rect(vec2 xy, vec2 h, int grid_x, int grid_y) {
    const float px = xy.x - 0.5, py = xy.y - 0.5;
    const float gx = float(grid_x), gy = float(grid_y);
    TileRect t;
    t.x0 = int(clampf((px - h.x) / float(TILE), 0.0, gx));
    t.y0 = int(clampf((py - h.y) / float(TILE), 0.0, gy));
    t.x1 = int(clampf((px + h.x + float(TILE - 1)) / float(TILE), 0.0, gx));
    t.y1 = int(clampf((py + h.y + float(TILE - 1)) / float(TILE), 0.0, gy));
    return t;
}

// port of preprocess.h: tile_footprint
bool tile_footprint(vec2 xy, vec2 h, int grid_x, int grid_y, out TileRect rect) {
    rect = TileRect(0, 0, 0, 0);
    if (!finitef(xy.x) || !finitef(xy.y) || !finitef(h.x) || !finitef(h.y)) return false;
    rect = tile_rect(xy, h, grid_x, grid_y);
    return rect.x1 > rect.x0 && rect.y1 > rect.y0;
}

// port of preprocess.h: screen_footprint
bool screen_footprint(CameraParams cam, vec3 pv, vec2 h, int grid_x, int grid_y, precise out vec2 xy,
                      out TileRect rect) {
    screen_position(cam, pv, xy);
    return tile_footprint(xy, h, grid_x, grid_y, rect);
}

// port of view_filter.h: scalar_filter (the viewer presets' 2D filter); false: culled
bool scalar_filter(OitParams f, inout precise vec3 cov, inout precise float opacity) {
    if (f.pre_dilation != 0.0) {
        cov[0] += f.pre_dilation;
        cov[2] += f.pre_dilation;
    }
    precise float det0 = 0.0;
    if (f.compensate != 0) det0 = cov[0] * cov[2] - cov[1] * cov[1];
    cov[0] += f.dilation;
    cov[2] += f.dilation;
    if (f.compensate != 0) {
        precise const float det1 = cov[0] * cov[2] - cov[1] * cov[1];
        opacity *= sqrt(max(0.0, det0 / det1));
    }
    if (f.cull_lambda > 0.0) {
        precise const float half_diff = 0.5 * (cov[0] - cov[2]);
        precise const float root = sqrt(half_diff * half_diff + cov[1] * cov[1]);
        precise const float lambda1 = 0.5 * (cov[0] + cov[2]) + root;
        if (!(lambda1 >= f.cull_lambda)) return false;
    }
    return true;
}

// port of view_filter.h: support_power
float support_power(OitParams f) {
    precise const float s2 = f.support * f.support;
    return f.support > 0.0 ? -0.5 * s2 : uintBitsToFloat(0xff800000u);
}

// port of preprocess.h: preprocess_finish (the mode's finish of a stored stage, but the colour; false: culled)
bool preprocess_finish(SplatIn in_, StageSplat st, int sh_deg, CameraParams cam, int mode, OitParams oit, int grid_x,
                       int grid_y, out Splat2D result, out TileRect rect) {
    rect = TileRect(0, 0, 0, 0);
    precise vec3 cov = st.cov;
    precise float opacity = st.opacity;
    float sigmas = RADIUS_SIGMAS_3DGS;
    float min_alpha = MIN_ALPHA_3DGS;
    float min_power = uintBitsToFloat(0xff800000u);
    if (view_filtered(mode) || mode == STOPTHEPOP) {
        if (!scalar_filter(oit, cov, opacity)) return false;
        min_power = support_power(oit);
    } else if (mode == MIP) {
        precise const float det0 = max(1e-6, cov[0] * cov[2] - cov[1] * cov[1]);
        cov[0] += MIP_KERNEL_SIZE;
        cov[2] += MIP_KERNEL_SIZE;
        precise const float det1 = max(1e-6, cov[0] * cov[2] - cov[1] * cov[1]);
        precise const float coef = (det0 <= 1e-6 || det1 <= 1e-6) ? 0.0 : sqrt(det0 / (det1 + 1e-6) + 1e-6);
        opacity *= coef;
    } else if (mode == GAUSSIAN_BLENDING) {
        sigmas = RADIUS_SIGMAS_GB;
        min_alpha = MIN_ALPHA_GB;
    } else if (mode == WSR || mode == DUPLEX) {
        cov[0] += DILATION_3DGS;
        cov[2] += DILATION_3DGS;
        precise float w = 1.0;
        if (in_.has_weight) {
            precise vec3 dir;
            view_direction(cam, in_.mean, dir);
            w = sh_to_weight(in_.index, sh_deg < in_.weight_deg ? sh_deg : in_.weight_deg, dir);
        }
        if (oit.depth_correct != 0) {
            if (!(st.depth < oit.sigma)) return false;
            w *= 1.0 - st.depth / oit.sigma;
        }
        if (!(w > 0.0)) return false;
        opacity *= w;
    }
    if (!(opacity >= min_alpha)) return false;  // alpha = opacity * g <= opacity would be skipped anyway

    precise const float det = cov[0] * cov[2] - cov[1] * cov[1];
    if (!(det > 0.0) || !finitef(det)) return false;
    const float inv = 1.0 / det;

    precise const float r = splat_radius(cov[0], cov[2], det, sigmas);
    if (!tile_footprint(st.xy, cutoff_half_sides(mode, cov, det, opacity, min_alpha, r), grid_x, grid_y, rect))
        return false;

    result.xy = st.xy;
    result.depth = st.depth;
    result.opacity = opacity;
    result.log_min_alpha = max(logf(min_alpha / opacity), min_power);
    result.conic[0] = cov[2] * inv;
    result.conic[1] = -cov[1] * inv;
    result.conic[2] = cov[0] * inv;
    eigen_2d(cov[0], cov[1], cov[2], det, result.sigma1, result.sigma2, result.v1);
    result.inv_sigma1 = 1.0 / result.sigma1;
    result.inv_sigma2 = 1.0 / result.sigma2;
    result.radius = r;
    result.cell = in_.cell;
    result.color = vec3(0.0);
    return true;
}

// port of preprocess.h: stage_splat (stage.comp)
bool stage_splat(SplatIn in_, int sh_deg, int rules, CameraParams cam, int grid_x, int grid_y, float reach,
                 out StageSplat st) {
    if (!preprocess_stage(in_, cam, rules, st) || !stage_on_screen(st, grid_x, grid_y, reach)) return false;
    stage_color(in_, sh_deg, rules, cam, st.color);
    return true;
}

// port of popfree.h: dot3_rn, minor_rn (vectors rather than strided pointers; `precise`: mul_rn's products)
float dot3_rn(vec3 a, vec3 b) {
    precise const float r = a.x * b.x + a.y * b.y + a.z * b.z;
    return r;
}
float minor_rn(float a, float b, float c, float d) {
    precise const float r = a * b - c * d;
    return r;
}

// port of popfree.h: popfree_plane (DepthPlane as a vec4)
vec4 popfree_plane(CameraParams cam, vec3 pv, float cov3[6]) {
    const mat3 S = mat3(cov3[0], cov3[1], cov3[2], cov3[1], cov3[3], cov3[4], cov3[2], cov3[4], cov3[5]);
    const vec3 R0 = vec3(cam.R[0], cam.R[1], cam.R[2]), R1 = vec3(cam.R[3], cam.R[4], cam.R[5]);
    const vec3 R2 = vec3(cam.R[6], cam.R[7], cam.R[8]);
    const vec3 rows[3] = vec3[3](R0, R1, R2);
    vec3 RS[3];
    for (int i = 0; i < 3; ++i) RS[i] = vec3(dot3_rn(rows[i], S[0]), dot3_rn(rows[i], S[1]), dot3_rn(rows[i], S[2]));
    float V[9];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) V[i * 3 + j] = dot3_rn(RS[i], rows[j]);
    const vec3 adj0 =
        vec3(minor_rn(V[4], V[8], V[5], V[7]), minor_rn(V[2], V[7], V[1], V[8]), minor_rn(V[1], V[5], V[2], V[4]));
    const vec3 adj1 =
        vec3(minor_rn(V[5], V[6], V[3], V[8]), minor_rn(V[0], V[8], V[2], V[6]), minor_rn(V[2], V[3], V[0], V[5]));
    const vec3 adj2 =
        vec3(minor_rn(V[3], V[7], V[4], V[6]), minor_rn(V[1], V[6], V[0], V[7]), minor_rn(V[0], V[4], V[1], V[3]));
    const bool ortho = cam.projection == ORTHOGRAPHIC;
    const vec3 dir = ortho ? vec3(0.0, 0.0, 1.0) : pv;
    const vec3 n = vec3(dot3_rn(adj0, dir), dot3_rn(adj1, dir), dot3_rn(adj2, dir));
    const float c = dot3_rn(n, pv);
    const float a = n.x / cam.fx, b = n.y / cam.fy;
    precise const float k = (ortho ? -c : n.z) - a * cam.cx - b * cam.cy;
    return vec4(a, b, k, ortho ? n.z : c);
}

// port of popfree.h: splat_popfree_plane (DepthPlane as a vec4)
vec4 splat_popfree_plane(CameraParams cam, SplatIn in_) {
    precise vec3 pv, s;
    precise float opacity = 1.0;
    precise float cov3[6];
    view_point(cam, in_.mean, pv);
    filter_3d_scales(in_, s, opacity);
    covariance_3d(in_.quat, s, cov3);
    return popfree_plane(cam, pv, cov3);
}

// port of preprocess.h: finish_splat (preprocess.comp)
bool finish_splat(SplatIn in_, StageSplat st, int sh_deg, CameraParams cam, int mode, OitParams oit, int grid_x,
                  int grid_y, out Splat2D result, out TileRect rect) {
    if (!preprocess_finish(in_, st, sh_deg, cam, mode, oit, grid_x, grid_y, result, rect)) return false;
    result.color = st.color;
    return true;
}

// port of preprocess.h: CellIn
struct CellIn {
    vec3 mean;
    vec3 scale;
    vec4 quat;
};

// port of preprocess.h: Cell2D
struct Cell2D {
    vec2 xy;
    float depth;
    float radius;
};

// port of preprocess.h: preprocess_cell
bool preprocess_cell(CellIn in_, CameraParams cam, int grid_x, int grid_y, out Cell2D result, out TileRect rect) {
    rect = TileRect(0, 0, 0, 0);
    const vec3 m = in_.mean;
    precise vec3 pv;
    if (!view_point(cam, m, pv)) return false;
    precise float cov3[6];
    precise vec3 cov;
    covariance_3d(in_.quat, in_.scale, cov3);
    project_covariance(cam, cov3, pv, cov);
    cov[0] += DILATION_3DGS;
    cov[2] += DILATION_3DGS;
    precise const float det = cov[0] * cov[2] - cov[1] * cov[1];
    if (!(det > 0.0) || !finitef(det)) return false;
    precise const float r = splat_radius(cov[0], cov[2], det, DUPLEX_CELL_SIGMAS);
    precise vec2 xy;
    if (!screen_footprint(cam, pv, vec2(r, r), grid_x, grid_y, xy, rect)) return false;
    result.xy = xy;
    result.depth = pv[2];
    result.radius = r;
    return true;
}
