// gbviewer._native.io: the INRIA .ply row scatter. One pass over a chunk of vertex rows (float32 columns, in any
// order) writes each value into the Scene's column arrays and does there the per-value checks of
// gbviewer.Scene.from_arrays (finite; SH and view weights within their limit), the quaternion normalisation it does
// (the same float32 operations in the same order, so the arrays are bit-identical) and the abs of filter_3D. Scales
// and opacities are copied raw: numpy activates them (its exp is the reference), and the loader checks them after.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/pair.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

#include "half.h"
#include "omp_shim.h"

namespace nb = nanobind;

namespace {

using Table = nb::ndarray<const float, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using Cols = nb::ndarray<const int32_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using Out = nb::ndarray<float, nb::c_contig, nb::device::cpu>;
using AnyOut = nb::ndarray<nb::c_contig, nb::device::cpu>;  // the SH: float32 or float16
using Keep = nb::ndarray<uint8_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;

// Column positions in the order of gbviewer.io.ply.InriaLayout.wanted: x y z, f_dc_0..2, opacity, scale_0..2,
// rot_0..3, then the f_rest_* (channel-major: all R coefficients, then G, then B), filter_3D, the view weights.
constexpr int XYZ = 0, DC = 3, OPACITY = 6, SCALE = 7, ROT = 10, REST = 14;

inline bool finite(float v) { return std::fabs(v) <= FLT_MAX; }  // false for NaN and +-inf

// Scene.from_arrays's normalisation of one (w,x,y,z) row: |q| as (w^2 + x^2) + (y^2 + z^2) (numpy's einsum order), a
// row whose squares overflow scaled by its largest component first; rows within 4 eps of unit length kept as they
// are, the others divided by max(|q|, 1e-12), those under 1e-12 made the identity.
inline void normalise(float* q) {
    auto norm = [q] { return std::sqrt((q[0] * q[0] + q[1] * q[1]) + (q[2] * q[2] + q[3] * q[3])); };
    float n = norm();
    if (std::isinf(n)) {
        const float m =
            std::max(std::max(std::fabs(q[0]), std::fabs(q[1])), std::max(std::fabs(q[2]), std::fabs(q[3])));
        for (int i = 0; i < 4; ++i) q[i] /= m;
        n = norm();
    }
    if (std::fabs(n - 1.0f) > 4 * FLT_EPSILON) {
        const float tiny = 1e-12f, d = std::max(n, tiny);
        for (int i = 0; i < 4; ++i) q[i] /= d;
        if (n < tiny) q[0] = 1.0f, q[1] = q[2] = q[3] = 0.0f;
    }
}

inline void store(float* p, float v) { *p = v; }
inline void store(uint16_t* p, float v) { *p = gbv::half_bits(v); }  // float16 bits

struct Maxima {
    float dc = 0.0f, rest = 0.0f;  // the largest |SH| of the rows (NaN skipped), for float16's range check
};

template <class SH>
void scatter_rows(const float* table, int64_t rows, int64_t stride, const int32_t* cols, int k, int weights,
                  bool has_filter, float max_sh, float* means, float* scales, float* quats, float* opac, SH* sh,
                  float* filter, float* weight, uint8_t* keep, Maxima& mx) {
    const int rest = k - 1, after = REST + 3 * rest;
    for (int64_t r = 0; r < rows; ++r) {
        const float* row = table + r * stride;
        bool ok = true;
        auto sh_value = [&](int col, float& top) {
            const float v = row[col], a = std::fabs(v);
            ok &= a <= max_sh;
            top = a > top ? a : top;
            return v;
        };
        for (int c = 0; c < 3; ++c) {
            const float v = row[cols[XYZ + c]];
            ok &= finite(v);
            means[r * 3 + c] = v;
            store(&sh[r * k * 3 + c], sh_value(cols[DC + c], mx.dc));
            scales[r * 3 + c] = row[cols[SCALE + c]];
        }
        for (int j = 0; j < rest; ++j)
            for (int c = 0; c < 3; ++c)
                store(&sh[(r * k + 1 + j) * 3 + c], sh_value(cols[REST + c * rest + j], mx.rest));
        opac[r] = row[cols[OPACITY]];
        float* q = quats + r * 4;
        for (int i = 0; i < 4; ++i) {
            q[i] = row[cols[ROT + i]];
            ok &= finite(q[i]);
        }
        normalise(q);
        if (has_filter) {
            filter[r] = std::fabs(row[cols[after]]);
            ok &= finite(filter[r]);
        }
        for (int i = 0; i < weights; ++i) {
            const float v = row[cols[after + has_filter + i]];
            ok &= std::fabs(v) <= max_sh;
            weight[r * weights + i] = v;
        }
        keep[r] = ok;
    }
}

void need(bool ok, const char* what) {
    if (!ok) throw std::invalid_argument(std::string("scatter_inria: ") + what);
}

std::pair<float, float> scatter_inria(const Table& table, const Cols& cols, Out means, Out scales, Out quats,
                                      Out opacities, AnyOut sh, std::optional<Out> filter_3d,
                                      std::optional<Out> weights, Keep keep, float max_sh, int threads) {
    const int64_t rows = (int64_t)table.shape(0), stride = (int64_t)table.shape(1);
    need(sh.ndim() == 3 && sh.shape(0) == (size_t)rows && sh.shape(2) == 3, "sh must be (rows, K, 3)");
    const int k = (int)sh.shape(1);
    const int w = weights ? (int)(weights->size() / std::max<int64_t>(rows, 1)) : 0;
    need(means.size() == (size_t)rows * 3 && scales.size() == (size_t)rows * 3 && quats.size() == (size_t)rows * 4 &&
             opacities.size() == (size_t)rows && keep.shape(0) == (size_t)rows &&
             (!filter_3d || filter_3d->size() == (size_t)rows) && (!weights || weights->size() == (size_t)rows * w),
         "output arrays must hold the table's rows");
    need(cols.shape(0) == (size_t)(REST + 3 * (k - 1) + (filter_3d ? 1 : 0) + w), "one column position per value");
    for (size_t i = 0; i < cols.shape(0); ++i)
        need(cols(i) >= 0 && cols(i) < stride, "column position outside the table");
    const bool half = sh.dtype() == nb::dlpack::dtype{(uint8_t)nb::dlpack::dtype_code::Float, 16, 1};
    need(half || sh.dtype() == nb::dtype<float>(), "sh must be float32 or float16");
    Maxima mx;
    {
        nb::gil_scoped_release release;
        float* f = filter_3d ? filter_3d->data() : nullptr;
        float* wt = weights ? weights->data() : nullptr;
        constexpr int64_t BLOCK = 4096;  // rows per task: each thread writes its own rows of every array
        const int64_t blocks = (rows + BLOCK - 1) / BLOCK;
        const int nt = gbv::team(threads);
#pragma omp parallel num_threads(nt)
        {
            Maxima local;
#pragma omp for schedule(static)
            for (int64_t b = 0; b < blocks; ++b) {
                const int64_t r0 = b * BLOCK, count = std::min(BLOCK, rows - r0);
                const float* t = table.data() + r0 * stride;
                float* fr = f ? f + r0 : nullptr;
                float* wr = wt ? wt + r0 * w : nullptr;
                if (half)
                    scatter_rows(t, count, stride, cols.data(), k, w, f != nullptr, max_sh, means.data() + r0 * 3,
                                 scales.data() + r0 * 3, quats.data() + r0 * 4, opacities.data() + r0,
                                 static_cast<uint16_t*>(sh.data()) + r0 * k * 3, fr, wr, keep.data() + r0, local);
                else
                    scatter_rows(t, count, stride, cols.data(), k, w, f != nullptr, max_sh, means.data() + r0 * 3,
                                 scales.data() + r0 * 3, quats.data() + r0 * 4, opacities.data() + r0,
                                 static_cast<float*>(sh.data()) + r0 * k * 3, fr, wr, keep.data() + r0, local);
            }
#pragma omp critical
            {
                mx.dc = std::max(mx.dc, local.dc);
                mx.rest = std::max(mx.rest, local.rest);
            }
        }
    }
    return {mx.dc, mx.rest};
}

}  // namespace

void bind_io(nb::module_& m) {
    nb::module_ io = m.def_submodule("io", "Scene-file decoding helpers of gbviewer.io.");
    io.def("scatter_inria", &scatter_inria, nb::arg("table"), nb::arg("cols"), nb::arg("means"), nb::arg("scales"),
           nb::arg("quats"), nb::arg("opacities"), nb::arg("sh"), nb::arg("filter_3d").none(),
           nb::arg("weights").none(), nb::arg("keep"), nb::arg("max_sh"), nb::arg("threads") = 0,
           "De-interleave INRIA vertex rows `table` (rows, C) float32 into the column arrays (slices of the Scene's "
           "arrays for those rows; sh float32 or float16), columns at `cols` (the order of InriaLayout.wanted "
           "without info). Quaternions normalised and filter_3D made >= 0 as Scene.from_arrays does; scales and "
           "opacities raw. keep[r] = 0 where a copied value is non-finite or an SH / view weight is beyond max_sh. "
           "Returns the largest |f_dc| and |f_rest| of the rows (NaN skipped). `threads`: OpenMP threads, 0: all.");
}
