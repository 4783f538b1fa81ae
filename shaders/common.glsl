// GLSL port of native/include/gbv/common.h, which documents it: the same constants with the same names and values,
// the same structs (Splat2D's storage layout is pack_splat's, kernel.glsl), and the float helpers the C++ code takes
// from <cmath>. tests/render/test_glsl_port.py fails when a constant, a struct field or its layout differs.

// port of common.h: Mode, Projection and the constants
const int SCALAR = 0;
const int MIP = 1;
const int ANALYTIC = 2;
const int GAUSSIAN_BLENDING = 3;
const int WSR = 4;
const int DUPLEX = 5;
const int STOCHASTIC = 6;
const int STOCHASTIC_POPFREE = 7;
const int EVAL3D = 8;
const int STOPTHEPOP = 9;

// port of common.h: view_filtered
bool view_filtered(int mode) { return mode == SCALAR || mode == STOCHASTIC || mode == STOCHASTIC_POPFREE; }

const int PERSPECTIVE = 0;
const int ORTHOGRAPHIC = 1;

const int TILE = 16;
const float DILATION_3DGS = 0.3;
const float MIP_KERNEL_SIZE = 0.1;
const float MAX_ALPHA = 0.99;
const float MIN_ALPHA_3DGS = 1.0 / 255.0;
const float MIN_ALPHA_GB = 1.0 / 256.0;
const float T_STOP = 1e-4;
const float RADIUS_SIGMAS_3DGS = 3.0;
const float RADIUS_SIGMAS_GB = 3.33021844;
const float GB_MIN_UV_DIFF = 0.1;
const float GB_MAX_UV_DIFF = 1e6;
const float GB_MIN_VAR = 0.001;
const float GB_SERIES_MAX_HALF_WIDTH = 1.0;
const int GB_SERIES_TERMS = 12;
const int GB_FAST_SERIES_TERMS = 8;
const float SQRT_PI_2 = 1.2533141373155003;
const float WSR_EMPTY_SUM = 1e-4;
const float WSR_FIXED_SCALE = 68719476736.0;
const float WSR_FIXED_MAX = 64.0;
const float DUPLEX_CELL_SIGMAS = 2.0;
const float DUPLEX_T_STOP = 0.01;
const float TWO_PI = 6.283185307179586;
const int STOPTHEPOP_QUEUE = 4;
const int MAX_QUEUE = 64;

// port of common.h: per_pixel_sorted
bool per_pixel_sorted(int m) { return m == EVAL3D || m == STOPTHEPOP; }

// port of common.h: clampf, minf, maxf
float clampf(float v, float lo, float hi) { return min(max(v, lo), hi); }
float minf(float a, float b) { return a < b ? a : b; }
float maxf(float a, float b) { return a > b ? a : b; }

// port of common.h: sh_degree_for_coeffs
int sh_degree_for_coeffs(int k) { return k >= 16 ? 3 : k >= 9 ? 2 : k >= 4 ? 1 : 0; }

// port of common.h: finitef
bool finitef(float v) { return !isnan(v) && !isinf(v); }

// port of common.h: CameraParams
struct CameraParams {
    float R[9];
    float t[3];
    float campos[3];
    float fx, fy, cx, cy;
    int width, height;
    float near_plane;
    float lim_x_neg, lim_x_pos, lim_y_neg, lim_y_pos;
    int projection;
};

// port of common.h: Splat2D
struct Splat2D {
    vec2 xy;
    float depth;
    float opacity;
    vec3 conic;
    vec3 color;
    vec2 v1;
    float sigma1, sigma2;
    float inv_sigma1, inv_sigma2;
    float log_min_alpha;
    float radius;
    int cell;
    int id;
};

// port of common.h: OitParams
struct OitParams {
    float sigma;
    float weight_background;
    float et_grade;
    int depth_correct;
    float dilation;
    float pre_dilation;
    float cull_lambda;
    int compensate;
    int dc_clamp;
    float support;
    int sort_radial;
};

// port of common.h: TileRect
struct TileRect {
    int x0, y0, x1, y1;
};
