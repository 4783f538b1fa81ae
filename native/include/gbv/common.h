// Shared definitions for the host (g++) and device (nvcc) builds of the gbviewer kernels.
#pragma once

#include <cmath>
#include <cstdint>

// GBV_HD: a kernel function for both compilers. On the host it has internal linkage, so the CPU's per-instruction-set
// translation units (native/cpu/, each built with its own -m flags) each keep their own copy: the linker cannot
// merge an AVX-512 copy into the baseline path. GBV_HDI: the same for member functions (always inlined).
#if defined(__CUDACC__)
#define GBV_HD __host__ __device__ __forceinline__
#define GBV_HDI __host__ __device__ __forceinline__
#else
#define GBV_HD static inline __attribute__((always_inline))
#define GBV_HDI inline __attribute__((always_inline))
#endif
// Fully unroll the loop that follows (fixed, small trip counts).
#if defined(__CUDACC__)
#define GBV_UNROLL _Pragma("unroll")
#elif defined(__GNUC__)
#define GBV_UNROLL _Pragma("GCC unroll 16")
#else
#define GBV_UNROLL
#endif

namespace gbv {

// Blending modes; the integer values are the Python enum's values (gbviewer/render/modes.py).
enum Mode : int32_t {
    SCALAR = 0,
    MIP = 1,
    ANALYTIC = 2,
    GAUSSIAN_BLENDING = 3,
    WSR = 4,
    DUPLEX = 5,
    STOCHASTIC = 6,
    STOCHASTIC_POPFREE = 7,
    EVAL3D = 8,
    STOPTHEPOP = 9,  // per-pixel sorted along the ray (ray3d.h)
};
// The modes whose alpha is 3DGS's at the pixel centre, with the viewer presets' 2D filter (view_filter.h): scalar and
// the stochastic modes, which keep fragments with that alpha (gbviewer.render.presets.FILTERED_MODES). stopthepop
// blends 3DGS's 2D splats through the same filter (preprocess_finish), but only with its default, 3DGS's +0.3: no
// preset or view filter takes it (gbviewer.render.RenderSettings refuses one).
GBV_HD constexpr bool view_filtered(Mode mode) {
    return mode == SCALAR || mode == STOCHASTIC || mode == STOCHASTIC_POPFREE;
}
// Modes that order each pixel's splats by the depth of their maximum along its ray (ray3d.h).
GBV_HD bool per_pixel_sorted(Mode m) { return m == EVAL3D || m == STOPTHEPOP; }
// Camera projections; the values are the indices of gbviewer.model.camera.PROJECTIONS.
enum Projection : int32_t { PERSPECTIVE = 0, ORTHOGRAPHIC = 1 };

constexpr int TILE = 16;  // BLOCK_X = BLOCK_Y (docs/modes.md#culling-radius-tiles)
constexpr float DILATION_3DGS = 0.3f;  // +0.3 px^2, no compensation (§0.3)
constexpr float MIP_KERNEL_SIZE = 0.1f;  // Mip-Splatting 2D filter (§2)
constexpr float MAX_ALPHA = 0.99f;
constexpr float MIN_ALPHA_3DGS = 1.0f / 255.0f;
constexpr float MIN_ALPHA_GB = 1.0f / 256.0f;  // Gaussian Blending uses 1/256 (§6.1)
constexpr float T_STOP = 1e-4f;  // early termination threshold
constexpr float RADIUS_SIGMAS_3DGS = 3.0f;
constexpr float RADIUS_SIGMAS_GB = 3.33021844f;  // sqrt(-2 ln(1/256))
constexpr float GB_MIN_UV_DIFF = 0.1f;  // window narrower than 0.1 sigma -> scalar fallback
constexpr float GB_MAX_UV_DIFF = 1e6f;
constexpr float GB_MIN_VAR = 0.001f;  // window variance floor
constexpr float GB_SERIES_MAX_HALF_WIDTH = 1.0f;  // window moments: Hermite series up to this half side (sigmas)
constexpr int GB_SERIES_TERMS = 12;
constexpr int GB_FAST_SERIES_TERMS = 8;  // the fast precision's longest series (window_side_moments' Fast)
constexpr float SQRT_PI_2 = 1.2533141373155003f;
constexpr float WSR_EMPTY_SUM = 1e-4f;  // LC-WSR: a weight sum of exactly 0 becomes 1e-4 (§7.2)
constexpr float WSR_FIXED_SCALE = 68719476736.0f;  // 2^36: CPU weighted sums in 64-bit fixed point (blend.h)
constexpr float WSR_FIXED_MAX = 64.0f;  // 2^6: per-term clamp; 2^21 - 1 such terms fit a fixed-point int64
constexpr float DUPLEX_CELL_SIGMAS = 2.0f;  // cell radius ceil(2 sqrt(lambda1)) (§8.3)
constexpr float DUPLEX_T_STOP = 0.01f;  // CUMMULT_THRESHOLD: cell-level early termination (§8.1)
constexpr float TWO_PI = 6.283185307179586f;
// StopThePop's published per-pixel queue length (SortQueueSizes.per_pixel = 4; tile_4x4 = 64, tile_2x2 = 8:
// r4dl/StopThePop-Rasterization diff_gaussian_rasterization/__init__.py; the sub-tile queues: resort.h).
constexpr int STOPTHEPOP_QUEUE = 4;
constexpr int MAX_QUEUE = 64;  // the longest per-pixel queue accepted (0: unbounded, the exact per-pixel sort)

struct Vec2 {
    float x, y;
};
struct Vec3 {
    float x, y, z;
};

GBV_HD Vec2 operator+(Vec2 a, Vec2 b) { return {a.x + b.x, a.y + b.y}; }
GBV_HD Vec2 operator-(Vec2 a, Vec2 b) { return {a.x - b.x, a.y - b.y}; }
GBV_HD Vec2 operator*(float s, Vec2 a) { return {s * a.x, s * a.y}; }
GBV_HD float dot(Vec2 a, Vec2 b) { return a.x * b.x + a.y * b.y; }

// a * b rounded to float, never fused with a following add or subtract into a multiply-add. Compilers contract
// a * b + c where they choose (g++ at -ffp-contract=fast, its default, with FMA hardware; nvcc by default), which
// changes the last bit of a sum, and a near-flat splat's det > 0, opacity >= min_alpha, w > 0 or an integer tile
// edge can then go the other way. preprocess.h and camera.h route every product that is added or subtracted
// through this, so the preprocessed splats (every field splat_less compares but log_min_alpha) and the culling
// decisions are bit-identical on every backend and compiler flag (tests/render/test_fp_contract.py; the GLSL port
// declares those values `precise`). Device: __fmul_rn, which nvcc never contracts. Host: the product passes
// through an empty asm statement, which the optimiser cannot see through (g++ ignores #pragma STDC FP_CONTRACT,
// and optimize attributes are lost when inlined). GBV_UNGUARDED_PRODUCTS (tests only) makes it a plain product.
GBV_HD float mul_rn(float a, float b) {
#if defined(__CUDA_ARCH__)
    return __fmul_rn(a, b);
#else
    float p = a * b;
#if defined(GBV_UNGUARDED_PRODUCTS)
#elif defined(__GNUC__) && (defined(__x86_64__) || (defined(__i386__) && defined(__SSE_MATH__)))
    __asm__("" : "+x"(p));
#elif defined(__GNUC__) && defined(__aarch64__)
    __asm__("" : "+w"(p));
#else
    volatile float v = p;
    p = v;
#endif
    return p;
#endif
}

GBV_HD float clampf(float v, float lo, float hi) { return fminf(fmaxf(v, lo), hi); }

// min/max for the per-pixel loops: single instructions, where fminf/fmaxf are libm calls on the host
// (their NaN rules stop the compiler inlining them). Like those, a NaN first argument yields the second.
GBV_HD float minf(float a, float b) { return a < b ? a : b; }
GBV_HD float maxf(float a, float b) { return a > b ? a : b; }

// SH degree whose (deg + 1)^2 coefficients fit in k per channel (k = 1, 4, 9, 16 -> 0..3).
GBV_HD int sh_degree_for_coeffs(int k) { return k >= 16 ? 3 : k >= 9 ? 2 : k >= 4 ? 1 : 0; }

GBV_HD bool finitef(float v) {
#if defined(__CUDA_ARCH__)
    return isfinite(v);
#else
    return std::isfinite(v);
#endif
}

// Camera as the kernels see it: world-to-camera rotation (row-major) and translation, intrinsics with pixel centres
// at half-integers (perspective: fx, fy in pixels, x = fx X/Z + cx; orthographic: fx, fy in pixels per world unit,
// x = fx X + cx), and the frustum limits used to clamp the perspective EWA Jacobian.
struct CameraParams {
    float R[9];
    float t[3];
    float campos[3];
    float fx, fy, cx, cy;
    int32_t width, height;
    float near_plane;
    float lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos;
    int32_t projection;  // PERSPECTIVE or ORTHOGRAPHIC
};

// Per-splat output of preprocess; everything the blend step needs, computed once per frame.
struct Splat2D {
    Vec2 xy;  // screen position (pixel centres at half-integers)
    float depth;  // view-space z
    float opacity;  // after the mode's compensation and the 3D filter
    float conic[3];  // inverse 2D covariance (a, b, c)
    float color[3];
    Vec2 v1;  // unit major eigenvector (v2 = perp(v1))
    float sigma1, sigma2;  // sqrt of the eigenvalues of the 2D covariance
    float inv_sigma1, inv_sigma2;
    float log_min_alpha;  // ln(min_alpha / opacity): lowest log-Gaussian value that can give a visible alpha
    float radius;  // screen-space bounding radius in pixels (duplex rejects pixels outside this circle)
    int32_t cell;  // index of the splat's cell (duplex), -1 otherwise
    int32_t id;  // the splat's index in the frame's splats (stochastic hashes it: stochastic.h)
};

// Per-frame mode globals. The order-independent modes (wsr, duplex): LC-WSR's depth correction max(0, 1 - z/sigma)
// when depth_correct is 1, the background weight w_bg, and Duplex-GS's ET_grade E (alpha / E inside cells). The
// scalar mode: the viewer presets' 2D filter (view_filter.h) and their rules (view_filter.h: stage_rules,
// support_power); the defaults are 3DGS's +0.3 dilation and none of the rules.
struct OitParams {
    float sigma;
    float weight_background;
    float et_grade;
    int32_t depth_correct;
    float dilation = DILATION_3DGS;
    float pre_dilation = 0.0f;
    float cull_lambda = 0.0f;
    int32_t compensate = 0;
    int32_t dc_clamp = 0;  // base colour clamped to [0, 1] before the view-dependent SH terms are added
    float support = 0.0f;  // alpha 0 beyond this Mahalanobis radius (sigmas); 0: no such cut
    int32_t sort_radial = 0;  // sort by distance from the eye instead of view-space z (perspective)
};

// Tile rectangle [x0, x1) x [y0, y1) in tile units.
struct TileRect {
    int32_t x0, y0, x1, y1;
};

}  // namespace gbv
