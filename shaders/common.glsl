// GLSL mirror of native/include/gbv/common.h: the same constants with the same names and values, the same
// structs (Splat2D's storage layout is in splat_storage.glsl), and the float helpers the C++ code takes from
// <cmath>. tests/render/test_glsl.py parses both files and fails when a constant differs or is missing.

// Blending modes; the integer values are the Python enum's values (gbviewer/render/types.py).
const int SCALAR = 0;
const int MIP = 1;
const int ANALYTIC = 2;
const int GAUSSIAN_BLENDING = 3;
const int WSR = 4;
const int DUPLEX = 5;

// Camera projections; the values are the indices of gbviewer.camera.PROJECTIONS.
const int PERSPECTIVE = 0;
const int ORTHOGRAPHIC = 1;

const int TILE = 16;                       // BLOCK_X = BLOCK_Y (KERNELS.md §0.4)
const float DILATION_3DGS = 0.3;           // +0.3 px^2, no compensation (§0.3)
const float MIP_KERNEL_SIZE = 0.1;         // Mip-Splatting 2D filter (§2)
const float MAX_ALPHA = 0.99;
const float MIN_ALPHA_3DGS = 1.0 / 255.0;
const float MIN_ALPHA_GB = 1.0 / 256.0;    // Gaussian Blending uses 1/256 (§6.1)
const float T_STOP = 1e-4;                 // early termination threshold
const float RADIUS_SIGMAS_3DGS = 3.0;
const float RADIUS_SIGMAS_GB = 3.33021844;   // sqrt(-2 ln(1/256))
const float GB_MIN_UV_DIFF = 0.1;          // window narrower than 0.1 sigma -> scalar fallback
const float GB_MAX_UV_DIFF = 1e6;
const float GB_MIN_VAR = 0.001;            // window variance floor
const float GB_SERIES_MAX_HALF_WIDTH = 1.0;  // window moments: Hermite series up to this half side (sigmas)
const int GB_SERIES_TERMS = 12;
const float SQRT_PI_2 = 1.2533141373155003;
const float WSR_EMPTY_SUM = 1e-4;          // LC-WSR: a weight sum of exactly 0 becomes 1e-4 (§7.2)
const float WSR_FIXED_SCALE = 68719476736.0;  // 2^36: the CPU's fixed-point sums (unused here: GLSL sums in float)
const float WSR_FIXED_MAX = 64.0;          // 2^6: the CPU's per-term clamp (applied here too, blend.glsl)
const float DUPLEX_CELL_SIGMAS = 2.0;      // cell radius ceil(2 sqrt(lambda1)) (§8.3)
const float DUPLEX_T_STOP = 0.01;          // CUMMULT_THRESHOLD: cell-level early termination (§8.1)
const float TWO_PI = 6.283185307179586;

float clampf(float v, float lo, float hi) { return min(max(v, lo), hi); }
float minf(float a, float b) { return a < b ? a : b; }
float maxf(float a, float b) { return a > b ? a : b; }

// SH degree whose (deg + 1)^2 coefficients fit in k per channel (k = 1, 4, 9, 16 -> 0..3).
int sh_degree_for_coeffs(int k) { return k >= 16 ? 3 : k >= 9 ? 2 : k >= 4 ? 1 : 0; }

bool finitef(float v) { return !isnan(v) && !isinf(v); }

// Camera as the kernels see it: world-to-camera rotation (row-major) and translation, intrinsics with pixel centres
// at half-integers (perspective: fx, fy in pixels, x = fx X/Z + cx; orthographic: fx, fy in pixels per world unit,
// x = fx X + cx), and the frustum limits used to clamp the perspective EWA Jacobian.
struct CameraParams {
    float R[9];
    float t[3];
    float campos[3];
    float fx, fy, cx, cy;
    int width, height;
    float near_plane;
    float lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos;
    int projection;  // PERSPECTIVE or ORTHOGRAPHIC
};

// Per-splat output of preprocess; everything the blend step needs, computed once per frame.
struct Splat2D {
    vec2 xy;         // screen position (pixel centres at half-integers)
    float depth;     // view-space z
    float opacity;   // after the mode's compensation and the 3D filter
    vec3 conic;      // inverse 2D covariance (a, b, c)
    vec3 color;
    vec2 v1;         // unit major eigenvector (v2 = perp(v1))
    float sigma1, sigma2;  // sqrt of the eigenvalues of the 2D covariance
    float inv_sigma1, inv_sigma2;
    float log_min_alpha;   // ln(min_alpha / opacity): lowest log-Gaussian value that can give a visible alpha
    float radius;    // screen-space bounding radius in pixels (duplex rejects pixels outside this circle)
    int cell;        // index of the splat's cell (duplex), -1 otherwise
};

// Globals of the order-independent modes (wsr, duplex): LC-WSR's depth correction max(0, 1 - z/sigma) when
// depth_correct is 1, the background weight w_bg, and Duplex-GS's ET_grade E (alpha / E inside cells).
struct OitParams {
    float sigma;
    float weight_background;
    float et_grade;
    int depth_correct;
};

// Tile rectangle [x0, x1) x [y0, y1) in tile units.
struct TileRect {
    int x0, y0, x1, y1;
};
