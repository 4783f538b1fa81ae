// CPU driver: preprocess (parallel over splats), per-tile binning and depth sort, blending
// (parallel over tiles, dynamic schedule). The math is in include/gbv/*.h, shared with CUDA.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <stdexcept>
#include <vector>

#include "gbv/blend.h"
#include "gbv/camera.h"
#include "gbv/preprocess.h"

namespace nb = nanobind;
using namespace gbv;

namespace {

using Clock = std::chrono::steady_clock;
double ms_since(Clock::time_point t0) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

struct SceneView {
    const float *means, *scales, *quats, *opacities, *sh, *filter_3d;
    int64_t n;
    int k;  // SH coefficients per channel
};

struct Image {
    int width = 0, height = 0;
    std::vector<float> rgb, alpha, window;
    std::vector<int32_t> evals;
    void resize(int w, int h, bool with_window) {
        width = w;
        height = h;
        const size_t px = (size_t)w * h;
        rgb.assign(px * 3, 0.0f);
        alpha.assign(px, 0.0f);
        evals.assign(px, 0);
        window.assign(with_window ? px * 2 : 0, 0.0f);
    }
};

struct Stats {
    double preprocess_ms = 0, sort_ms = 0, blend_ms = 0;
    int64_t visible = 0, sort_length = 0, evaluations = 0;
};

// Render one image at the camera's resolution, one sample per pixel.
void render_image(const SceneView& sc, const CameraParams& cam, Mode mode, int sh_deg, const float bg[3],
                  Image& img, Stats& st) {
    const int W = cam.width, H = cam.height;
    const int gx = (W + TILE - 1) / TILE, gy = (H + TILE - 1) / TILE;
    const int num_tiles = gx * gy;
    const int64_t n = sc.n;

    auto t0 = Clock::now();
    std::vector<Splat2D> splats(n);
    std::vector<TileRect> rects(n);
    std::vector<uint8_t> valid(n);
#pragma omp parallel for schedule(static)
    for (int64_t i = 0; i < n; ++i) {
        SplatIn in{sc.means + 3 * i, sc.scales + 3 * i, sc.quats + 4 * i, sc.opacities[i],
                   sc.sh + (size_t)sc.k * 3 * i, sc.filter_3d ? sc.filter_3d[i] : 0.0f};
        valid[i] = preprocess_splat(in, sh_deg, cam, mode, gx, gy, &splats[i], &rects[i]);
    }
    st.preprocess_ms += ms_since(t0);

    // Binning: count per tile, prefix sum, scatter splat ids, then sort each tile's list by depth.
    t0 = Clock::now();
    std::vector<int64_t> tile_start(num_tiles + 1, 0);
    int64_t visible = 0;
    for (int64_t i = 0; i < n; ++i) {
        if (!valid[i]) continue;
        ++visible;
        const TileRect& r = rects[i];
        for (int ty = r.y0; ty < r.y1; ++ty)
            for (int tx = r.x0; tx < r.x1; ++tx) ++tile_start[ty * gx + tx + 1];
    }
    for (int t = 0; t < num_tiles; ++t) tile_start[t + 1] += tile_start[t];
    const int64_t total = tile_start[num_tiles];
    std::vector<uint64_t> keys(total);
    {
        std::vector<int64_t> cursor(tile_start.begin(), tile_start.end() - 1);
        for (int64_t i = 0; i < n; ++i) {
            if (!valid[i]) continue;
            uint32_t depth_bits;
            std::memcpy(&depth_bits, &splats[i].depth, 4);  // depth > near > 0: bits sort as floats
            const uint64_t key = ((uint64_t)depth_bits << 32) | (uint32_t)i;
            const TileRect& r = rects[i];
            for (int ty = r.y0; ty < r.y1; ++ty)
                for (int tx = r.x0; tx < r.x1; ++tx) keys[cursor[ty * gx + tx]++] = key;
        }
    }
#pragma omp parallel for schedule(dynamic, 4)
    for (int t = 0; t < num_tiles; ++t) std::sort(keys.begin() + tile_start[t], keys.begin() + tile_start[t + 1]);
    st.sort_ms += ms_since(t0);
    st.visible += visible;
    st.sort_length += total;

    // Blend: each tile copies its splats into a contiguous per-thread buffer, then blends its pixels.
    t0 = Clock::now();
    int64_t evaluations = 0;
    const bool want_window = !img.window.empty();
#pragma omp parallel reduction(+ : evaluations)
    {
        std::vector<Splat2D> local;
#pragma omp for schedule(dynamic, 1)
        for (int t = 0; t < num_tiles; ++t) {
            const int64_t begin = tile_start[t], count = tile_start[t + 1] - begin;
            local.resize(count);
            for (int64_t j = 0; j < count; ++j) local[j] = splats[(uint32_t)keys[begin + j]];
            const Splat2D* list = local.data();
            const int x0 = (t % gx) * TILE, y0 = (t / gx) * TILE;
            for (int y = y0; y < std::min(y0 + TILE, H); ++y) {
                for (int x = x0; x < std::min(x0 + TILE, W); ++x) {
                    const Vec2 pix = {x + 0.5f, y + 0.5f};
                    const PixelOut o =
                        blend_pixel(mode, pix, (int)count, [list](int i) -> const Splat2D& { return list[i]; });
                    const size_t p = (size_t)y * W + x;
                    for (int c = 0; c < 3; ++c) img.rgb[p * 3 + c] = o.C[c] + o.T * bg[c];
                    img.alpha[p] = 1.0f - o.T;
                    img.evals[p] = o.evals;
                    if (want_window) {
                        img.window[p * 2] = o.window.x;
                        img.window[p * 2 + 1] = o.window.y;
                    }
                    evaluations += o.evals;
                }
            }
        }
    }
    st.blend_ms += ms_since(t0);
    st.evaluations += evaluations;
}

// Box-average N x N blocks of `hi` into `lo` (supersampling).
void box_downsample(const Image& hi, int N, Image& lo) {
    const float inv = 1.0f / (N * N);
    const bool with_window = !hi.window.empty();
#pragma omp parallel for schedule(static)
    for (int y = 0; y < lo.height; ++y) {
        for (int x = 0; x < lo.width; ++x) {
            float acc[6] = {0, 0, 0, 0, 0, 0};
            int32_t ev = 0;
            for (int sy = 0; sy < N; ++sy) {
                for (int sx = 0; sx < N; ++sx) {
                    const size_t q = (size_t)(y * N + sy) * hi.width + (x * N + sx);
                    for (int c = 0; c < 3; ++c) acc[c] += hi.rgb[q * 3 + c];
                    acc[3] += hi.alpha[q];
                    if (with_window) {
                        acc[4] += hi.window[q * 2];
                        acc[5] += hi.window[q * 2 + 1];
                    }
                    ev += hi.evals[q];
                }
            }
            const size_t p = (size_t)y * lo.width + x;
            for (int c = 0; c < 3; ++c) lo.rgb[p * 3 + c] = acc[c] * inv;
            lo.alpha[p] = acc[3] * inv;
            lo.evals[p] = ev;
            if (with_window) {
                lo.window[p * 2] = acc[4] * inv / N;  // in output pixels
                lo.window[p * 2 + 1] = acc[5] * inv / N;
            }
        }
    }
}

template <typename T>
nb::ndarray<nb::numpy, T> to_numpy(std::vector<T>&& v, std::initializer_list<size_t> shape) {
    auto* heap = new std::vector<T>(std::move(v));
    nb::capsule owner(heap, [](void* p) noexcept { delete static_cast<std::vector<T>*>(p); });
    return nb::ndarray<nb::numpy, T>(heap->data(), shape, owner);
}

using FArr = nb::ndarray<const float, nb::c_contig, nb::device::cpu>;

nb::dict render(FArr means, FArr scales, FArr quats, FArr opacities, FArr sh, std::optional<FArr> filter_3d,
                FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height, float near_plane,
                int mode, int supersample, int sh_degree, FArr background, bool want_window, int threads) {
    const int64_t n = (int64_t)means.shape(0);
    if (means.ndim() != 2 || means.shape(1) != 3 || scales.size() != (size_t)n * 3 || quats.size() != (size_t)n * 4 ||
        opacities.size() != (size_t)n || sh.ndim() != 3 || sh.shape(0) != (size_t)n || sh.shape(2) != 3 ||
        (filter_3d && filter_3d->size() != (size_t)n) || R.size() != 9 || t.size() != 3 || background.size() != 3)
        throw std::invalid_argument("render: array shapes do not match (N,3) means/scales, (N,4) quats, "
                                    "(N,) opacities, (N,K,3) sh, (N,) filter_3d, 3x3 R, 3 t, 3 background");
    if (mode < SCALAR || mode > GAUSSIAN_BLENDING) throw std::invalid_argument("render: unknown mode");
    if (supersample < 1 || supersample > 8) throw std::invalid_argument("render: supersample must be 1..8");
    const int k = (int)sh.shape(1);
    const int max_deg = k >= 16 ? 3 : k >= 9 ? 2 : k >= 4 ? 1 : 0;
    const int sh_deg = std::max(0, std::min(sh_degree, max_deg));
    SceneView sc{means.data(), scales.data(), quats.data(), opacities.data(), sh.data(),
                 filter_3d ? filter_3d->data() : nullptr, n, k};
    const int N = supersample;
    const CameraParams cam = make_camera(R.data(), t.data(), fx * N, fy * N, cx * N, cy * N, width * N,
                                         height * N, near_plane);
    const float bg[3] = {background.data()[0], background.data()[1], background.data()[2]};
    const bool window = want_window && mode == GAUSSIAN_BLENDING;

    Image out;
    Stats st;
    {
        nb::gil_scoped_release release;
        const int prev_threads = omp_get_max_threads();
        if (threads > 0) omp_set_num_threads(threads);
        out.resize(width, height, window);
        if (N == 1) {
            render_image(sc, cam, (Mode)mode, sh_deg, bg, out, st);
        } else {
            Image hi;
            hi.resize(width * N, height * N, window);
            render_image(sc, cam, (Mode)mode, sh_deg, bg, hi, st);
            auto t0 = Clock::now();
            box_downsample(hi, N, out);
            st.blend_ms += ms_since(t0);
        }
        if (threads > 0) omp_set_num_threads(prev_threads);
    }
    const size_t H = height, W = width;
    nb::dict d;
    d["rgb"] = to_numpy(std::move(out.rgb), {H, W, 3});
    d["alpha"] = to_numpy(std::move(out.alpha), {H, W});
    d["evals"] = to_numpy(std::move(out.evals), {H, W});
    if (window) d["window"] = to_numpy(std::move(out.window), {H, W, 2});
    d["preprocess_ms"] = st.preprocess_ms;
    d["sort_ms"] = st.sort_ms;
    d["blend_ms"] = st.blend_ms;
    d["visible"] = st.visible;
    d["sort_length"] = st.sort_length;
    d["evaluations"] = st.evaluations;
    return d;
}

}  // namespace

NB_MODULE(_native, m) {
    m.doc() = "gbviewer CPU renderer (C++17, OpenMP)";
    m.def("render", &render, nb::arg("means"), nb::arg("scales"), nb::arg("quats"), nb::arg("opacities"),
          nb::arg("sh"), nb::arg("filter_3d").none(), nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"),
          nb::arg("cx"), nb::arg("cy"), nb::arg("width"), nb::arg("height"), nb::arg("near_plane"),
          nb::arg("mode"), nb::arg("supersample"), nb::arg("sh_degree"), nb::arg("background"),
          nb::arg("want_window"), nb::arg("threads"));
    m.def("max_threads", []() { return omp_get_max_threads(); });
}
