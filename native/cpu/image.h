// An image's planes on the CPU (rgb, alpha, evals, the gaussian_blending window) and the box average that
// supersampling ends with: shared by the render (frame.cpp, renderer.cpp) and the pixel trace (trace.cpp).
#pragma once

#include <cstdint>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "plane.h"

namespace gbv {

struct Image {
    int width = 0, height = 0;
    Plane<float> rgb, alpha, window;
    Plane<int32_t> evals;
    // Planes of w x h pixels, their values unspecified until the blend writes them (`poison`: NaN and -1 instead, for
    // the test that shows every pixel written).
    void resize(int w, int h, bool with_window, bool poison = false) {
        width = w;
        height = h;
        const size_t px = (size_t)w * h;
        rgb.resize(px * 3);
        alpha.resize(px);
        evals.resize(px);
        window.resize(with_window ? px * 2 : 0);
        if (poison) {
            const float nan = std::numeric_limits<float>::quiet_NaN();
            for (auto* p : {&rgb, &alpha, &window}) p->assign(p->size(), nan);
            evals.assign(px, -1);
        }
    }
};

// Box-average N x N blocks of `hi` into `lo` (supersampling).
inline void box_downsample(const Image& hi, int N, Image& lo) {
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

}  // namespace gbv
