// nanobind module gbviewer._native: the CPU Renderer (renderer.h) behind the same call shape as the CUDA module,
// the SIMD path queries, and the test switches in _native.testing.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <functional>
#include <memory>
#include <string>
#include <stdexcept>
#include <tuple>

#include "../bindings/nb_common.h"
#include "frame.h"
#include "lod_args.h"
#include "renderer.h"
#include "simd.h"
#include "testing.h"
#include "trace_dict.h"

namespace nb = nanobind;
using namespace gbv;
using namespace gbv::nbc;
using cpu::Renderer;
using LArr = nb::ndarray<const int64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;  // the caller's cancel flag
using PArr = nb::ndarray<float, nb::ndim<3>, nb::c_contig, nb::device::cpu>;  // a partial frame, written here

void bind_io(nb::module_& m);  // io_scatter.cpp: _native.io
void bind_testing(nb::module_& m);  // testing_bind.cpp: _native.testing

namespace {

// An owner for Renderer::upload*: holds the arrays (references to the caller's numpy arrays, or the converted copies
// nanobind made) until the renderer lets go of them, from whichever thread that is.
template <class... A>
std::shared_ptr<const void> hold(A... arrays) {
    using Held = std::tuple<A...>;
    return std::shared_ptr<const void>(new Held(std::move(arrays)...), [](const void* p) {
        nb::gil_scoped_acquire gil;
        delete static_cast<const Held*>(p);
    });
}

// on_progress(frame, done, total) as Control::report: with the GIL, on the calling thread; an exception stops the call
// and is raised when it returns.
std::function<bool(int, int64_t, int64_t)> reporter(const std::optional<nb::callable>& on_progress, bool with_frame) {
    if (!on_progress) return {};
    return [&on_progress, with_frame](int frame, int64_t done, int64_t total) {
        nb::gil_scoped_acquire gil;
        try {
            if (with_frame) {
                (*on_progress)(frame, done, total);
            } else {
                (*on_progress)(done, total);
            }
            return true;
        } catch (nb::python_error& e) {
            e.restore();
            return false;
        }
    };
}

void check_partial(const char* where, const PArr& partial, int width, int height) {
    if (partial.shape(0) != (size_t)height || partial.shape(1) != (size_t)width || partial.shape(2) != 3)
        throw std::invalid_argument(std::string(where) + ": partial must be float32 (height, width, 3)");
}

std::vector<nb::dict> run_frames(Renderer& r, const std::vector<RenderArgs>& frames, cpu::Control& c) {
    std::vector<cpu::RenderResult> res;
    {
        nb::gil_scoped_release release;
        res = r.render_many(frames, c);
    }
    if (!res.empty() && res[0].stopped && PyErr_Occurred()) throw nb::python_error();
    std::vector<nb::dict> out;
    for (size_t f = 0; f < res.size(); ++f) {
        const RenderArgs& a = frames[f];
        nb::dict d =
            result_dict(res[f].image, res[f].stats, (size_t)(a.rw ? a.rh : a.height), (size_t)(a.rw ? a.rw : a.width));
        d["simd"] = res[f].simd;
        d["fast"] = frames[f].fast && frames[f].mode == GAUSSIAN_BLENDING;  // the kernel that ran
        d["cancelled"] = res[f].cancelled;
        d["stage_ms"] = res[f].stats.stage_ms;
        d["order_ms"] = res[f].stats.order_ms;
        d["stage_reused"] = res[f].stats.stage_reused;
        d["order_reused"] = res[f].stats.order_reused;
        if (res[f].stats.lod_drawn >= 0) d["lod_splats"] = res[f].stats.lod_drawn;
        out.push_back(std::move(d));
    }
    return out;
}

// A frame's part (x, y, w, h) in output pixels, or None: all of it (RenderArgs::rx .. rh).
void set_region(const char* where, RenderArgs& a, nb::handle region) {
    if (region.is_none()) return;
    const nb::tuple r = nb::cast<nb::tuple>(region);
    if (r.size() != 4) throw std::invalid_argument(std::string(where) + ": region must be (x, y, w, h)");
    const int x = nb::cast<int>(r[0]), y = nb::cast<int>(r[1]), w = nb::cast<int>(r[2]), h = nb::cast<int>(r[3]);
    if (x < 0 || y < 0 || w < 1 || h < 1 || x > a.width - w || y > a.height - h)
        throw std::invalid_argument(std::string(where) + ": region must be (x, y, w, h) inside the image");
    if ((int64_t)x * a.supersample % TILE || (int64_t)y * a.supersample % TILE)
        throw std::invalid_argument(std::string(where) + ": region x and y times supersample must be multiples of " +
                                    std::to_string(TILE));
    a.rx = x, a.ry = y, a.rw = w, a.rh = h;
}

nb::dict render(Renderer& r, FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height,
                float near_plane, int projection, int mode, int supersample, int sh_degree, FArr background,
                bool want_window, float sigma, float weight_background, float et_grade, bool depth_correct, int threads,
                std::optional<LArr> cancel, std::optional<nb::callable> on_progress, std::optional<PArr> partial,
                std::optional<FArr> view_filter, nb::handle lod, uint32_t seed, uint32_t frame, bool fast) {
    RenderArgs a = render_args("render", R, t, fx, fy, cx, cy, width, height, near_plane, projection, mode, supersample,
                               sh_degree, background, want_window, sigma, weight_background, et_grade, depth_correct,
                               view_filter, seed, frame);
    a.fast = fast;
    a.lod = lod_args("render", lod);
    if (cancel && cancel->shape(0) < 1) throw std::invalid_argument("render: cancel must hold at least one int64");
    if (partial) check_partial("render", *partial, width, height);
    cpu::Control c;
    c.cancel = cancel ? cancel->data() : nullptr;
    if (partial) c.partial = {partial->data()};
    c.threads = threads;
    c.report = reporter(on_progress, false);
    return run_frames(r, {a}, c)[0];
}

// render()'s arguments R .. depth_correct, view_filter (None: 3DGS's), lod (None: every splat), seed and frame of
// each frame, as one tuple per frame.
std::vector<nb::dict> render_many(Renderer& r, const std::vector<nb::tuple>& frames, int threads,
                                  std::optional<LArr> cancel, std::optional<nb::callable> on_progress,
                                  std::optional<std::vector<std::optional<PArr>>> partials) {
    const char* where = "render_many";
    if (cancel && cancel->shape(0) < 1) throw std::invalid_argument("render_many: cancel must hold at least one int64");
    if (partials && partials->size() != frames.size())
        throw std::invalid_argument("render_many: partials must have one entry (or None) per frame");
    std::vector<RenderArgs> args;
    cpu::Control c;
    for (size_t f = 0; f < frames.size(); ++f) {
        const nb::tuple& p = frames[f];
        if (p.size() != 24 && p.size() != 25)
            throw std::invalid_argument(
                "render_many: each frame is render()'s 19 frame arguments, view_filter, lod, "
                "seed, frame and fast, and optionally its region");
        std::optional<FArr> view_filter;
        if (!p[19].is_none()) view_filter = nb::cast<FArr>(p[19]);
        args.push_back(render_args(where, nb::cast<FArr>(p[0]), nb::cast<FArr>(p[1]), nb::cast<float>(p[2]),
                                   nb::cast<float>(p[3]), nb::cast<float>(p[4]), nb::cast<float>(p[5]),
                                   nb::cast<int>(p[6]), nb::cast<int>(p[7]), nb::cast<float>(p[8]), nb::cast<int>(p[9]),
                                   nb::cast<int>(p[10]), nb::cast<int>(p[11]), nb::cast<int>(p[12]),
                                   nb::cast<FArr>(p[13]), nb::cast<bool>(p[14]), nb::cast<float>(p[15]),
                                   nb::cast<float>(p[16]), nb::cast<float>(p[17]), nb::cast<bool>(p[18]), view_filter,
                                   nb::cast<uint32_t>(p[21]), nb::cast<uint32_t>(p[22])));
        args.back().lod = lod_args(where, p[20]);
        args.back().fast = nb::cast<bool>(p[23]);
        if (p.size() == 25) set_region(where, args.back(), p[24]);
        const std::optional<PArr>* part = partials ? &(*partials)[f] : nullptr;
        if (part && *part && args.back().rw)
            throw std::invalid_argument("render_many: a frame with a region has no partial frame");
        if (part && *part) check_partial(where, **part, args.back().width, args.back().height);
        c.partial.push_back(part && *part ? (*part)->data() : nullptr);
    }
    c.cancel = cancel ? cancel->data() : nullptr;
    c.threads = threads;
    c.report = reporter(on_progress, true);
    return run_frames(r, args, c);
}

}  // namespace

namespace gbv {
void bind_lod(nb::module_& m);  // lod_bind.cpp
}

NB_MODULE(_native, m) {
    m.doc() =
        "gbviewer CPU renderer (C++17, OpenMP; blend vectorised with Google Highway, chosen at run time). One "
        "Renderer may be shared by threads: its calls are serialised, and renders release the GIL.";
    simd::init_from_env();
    m.def("simd", [] { return std::string(simd::current().name); }, "The SIMD path renders use.");
    m.def(
        "simd_paths",
        [] {
            std::vector<std::string> names;
            for (const simd::Path* p : simd::supported()) names.push_back(p->name);
            return names;
        },
        "SIMD paths this CPU and build can run, best last.");
    m.def(
        "build_info",
        [] {
            nb::dict d;
            std::vector<std::string> built;
            for (const simd::Path* p : simd::built()) built.push_back(p->name);
            d["simd_built"] = built;
            std::vector<std::string> usable;
            for (const simd::Path* p : simd::supported()) usable.push_back(p->name);
            d["simd_usable"] = usable;
            d["simd_selected"] = std::string(simd::current().name);
#ifdef GBV_SCALAR_ONLY
            d["scalar_only"] = true;
#else
            d["scalar_only"] = false;
#endif
#ifdef _OPENMP
            d["openmp"] = std::string(GBV_BUILD_OPENMP) + " (_OPENMP " + std::to_string(_OPENMP) + ")";
#else
            d["openmp"] = nb::none();
#endif
#ifdef GBV_BUILD_CUDA
            d["cuda_module_built"] = true;
#else
            d["cuda_module_built"] = false;
#endif
            d["compiler"] = GBV_BUILD_COMPILER;
            d["build_type"] = GBV_BUILD_TYPE;
            d["flags"] = GBV_BUILD_FLAGS;
            d["isa_flags"] = GBV_BUILD_ISA_FLAGS;
            d["highway"] = std::string(GBV_BUILD_HIGHWAY).empty() ? nb::none() : nb::object(nb::str(GBV_BUILD_HIGHWAY));
            return d;
        },
        "How this module was built: SIMD paths built, usable here and selected; scalar-only switch; OpenMP version "
        "(None without); whether the CUDA module was built alongside; compiler, build type and compile flags; the "
        "version of Google Highway's headers the vector paths were built with (None without vector paths).");
    bind_testing(m);
    bind_io(m);
    bind_lod(m);
    nb::class_<Renderer>(m, "Renderer")
        .def(nb::init<>())
        .def(
            "upload",
            [](Renderer& r, FArr means, FArr scales, FArr quats, FArr opacities, FArr sh,
               std::optional<FArr> filter_3d) {
                const int64_t n = check_scene("upload", means, scales, quats, opacities, sh, filter_3d);
                const float* f3d = filter_3d ? filter_3d->data() : nullptr;
                std::shared_ptr<const void> owner = hold(means, scales, quats, opacities, sh, filter_3d);
                nb::gil_scoped_release release;
                r.upload(means.data(), scales.data(), quats.data(), opacities.data(), sh.data(), f3d, n,
                         (int)sh.shape(1), std::move(owner));
            },
            GBV_SCENE_ARGS,
            "The scene (activated parameters, gbviewer.Scene's arrays), referenced until the next upload: keep "
            "them unchanged meanwhile. Forgets the view weights and cells.")
        .def_prop_ro("num_splats", &Renderer::num_splats)
        .def(
            "upload_lod",
            [](Renderer& r, FArr means, FArr scales, FArr quats, FArr opacities, FArr sh, std::optional<FArr> filter_3d,
               FArr radius, FArr size, L64 levels, IArr order) {
                std::pair<int, bool> layout;
                {
                    nb::gil_scoped_release release;  // waits for a running render, whose report may take the GIL
                    layout = r.scene_layout();
                }
                const auto [k, filter] = layout;
                check_lod_upload(r.num_splats(), means, scales, quats, opacities, sh, filter_3d, radius, size, levels,
                                 order, k, filter);
                const float* f3d = filter_3d ? filter_3d->data() : nullptr;
                std::shared_ptr<const void> owner =
                    hold(means, scales, quats, opacities, sh, filter_3d, radius, size, levels, order);
                nb::gil_scoped_release release;
                r.upload_lod(means.data(), scales.data(), quats.data(), opacities.data(), sh.data(), k, f3d,
                             radius.data(), size.data(), levels.data(), (int)levels.size(), order.data(),
                             std::move(owner));
            },
            GBV_SCENE_ARGS, nb::arg("radius"), nb::arg("size"), nb::arg("levels"), nb::arg("order"),
            "The uploaded scene's splat hierarchy (gbviewer.lod.Hierarchy's arrays: interior nodes' Gaussians, "
            "radius, size, levels, order), referenced until the next upload; render(lod=...) draws its cuts.")
        .def(
            "upload_weights",
            [](Renderer& r, FArr weight_sh) {
                const int k = check_weight_sh("upload_weights", weight_sh, r.num_splats());
                std::shared_ptr<const void> owner = hold(weight_sh);
                nb::gil_scoped_release release;
                r.upload_weights(weight_sh.data(), (int64_t)weight_sh.shape(0), k, std::move(owner));
            },
            nb::arg("weight_sh"), "The uploaded scene's sort-free view-weight SH (N, K), for wsr and duplex.")
        .def(
            "upload_cells",
            [](Renderer& r, FArr means, FArr scales, FArr quats, IArr offsets, IArr members, IArr cell_of) {
                const int64_t m = check_cell_arrays("upload_cells", means, scales, quats, offsets);
                const int64_t n = r.num_splats();
                const std::vector<int32_t> expect =
                    partition_cell_of("upload_cells", offsets.data(), members.data(), m, (int64_t)members.size(), n);
                if (cell_of.size() != (size_t)n || !std::equal(expect.begin(), expect.end(), cell_of.data()))
                    throw std::invalid_argument(
                        "upload_cells: cell_of must give each of the scene's splats its cell "
                        "in the partition (-1: none)");
                std::shared_ptr<const void> owner = hold(means, scales, quats, offsets, members);
                nb::gil_scoped_release release;
                r.upload_cells(means.data(), scales.data(), quats.data(), offsets.data(), members.data(), expect.data(),
                               m, (int64_t)members.size(), std::move(owner));
            },
            nb::arg("means"), nb::arg("scales"), nb::arg("quats"), nb::arg("offsets"), nb::arg("members"),
            nb::arg("cell_of"), "Duplex cells of the uploaded scene (checked to be a partition of its splats).")
        .def("render", &render, nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"), nb::arg("cx"), nb::arg("cy"),
             nb::arg("width"), nb::arg("height"), nb::arg("near_plane"), nb::arg("projection"), nb::arg("mode"),
             nb::arg("supersample"), nb::arg("sh_degree"), nb::arg("background"), nb::arg("want_window"),
             nb::arg("sigma") = 10.0f, nb::arg("weight_background") = 1.0f, nb::arg("et_grade") = 4.0f,
             nb::arg("depth_correct") = false, nb::arg("threads") = 0, nb::arg("cancel").none() = nb::none(),
             nb::arg("on_progress").none() = nb::none(), nb::arg("partial").none() = nb::none(),
             nb::arg("view_filter").none() = nb::none(), nb::arg("lod").none() = nb::none(), nb::arg("seed") = 0,
             nb::arg("frame") = 0, nb::arg("fast") = false,
             "Render a frame of the uploaded scene. cancel: int64 array whose [0] stops the frame once nonzero (read "
             "by every worker); on_progress(done, total): called on this thread between tiles, at most every 5 ms, "
             "and at the end (an exception it raises stops the frame and is raised here); partial: float32 "
             "(height, width, 3) receiving each finished tile; view_filter: the scalar mode's [dilation, pre_dilation, "
             "cull_lambda, compensate, dc_clamp, support, sort_radial] (none: 3DGS's); lod: (tau, band, eye, focal, "
             "orthographic) draws the cut through the uploaded hierarchy in place (none: every splat); seed, frame: "
             "the stochastic mode's hash inputs; fast: gaussian_blending at the fast precision. The dict's lod_splats: "
             "the "
             "cut's size.")
        .def("render_many", &render_many, nb::arg("frames"), nb::arg("threads") = 0,
             nb::arg("cancel").none() = nb::none(), nb::arg("on_progress").none() = nb::none(),
             nb::arg("partials").none() = nb::none(),
             "Render several frames of the uploaded scene in one call (each a tuple of render()'s arguments R .. "
             "depth_correct, then view_filter and lod, each or None, then seed, frame and fast, and optionally the "
             "region (x, y, w, h) of output pixels rendered, x and y times supersample multiples of 16, or None): "
             "the per-camera stage once per distinct camera and SH "
             "degree, then every frame's tiles interleaved in one parallel loop. cancel as render's; "
             "on_progress(frame, done, total); partials: one float32 (height, width, 3) array or None per frame. A "
             "list of render()'s dicts, which also hold stage_ms, order_ms, stage_reused and order_reused.")
        .def(
            "trace",
            [](Renderer& r, FArr R, FArr t, float fx, float fy, float cx, float cy, int width, int height,
               float near_plane, int projection, int mode, int supersample, int sh_degree, FArr background, float sigma,
               float weight_background, float et_grade, bool depth_correct, int x, int y,
               std::optional<FArr> view_filter, nb::handle lod, uint32_t seed, uint32_t frame, bool fast) {
                RenderArgs a = render_args("trace", R, t, fx, fy, cx, cy, width, height, near_plane, projection, mode,
                                           supersample, sh_degree, background, false, sigma, weight_background,
                                           et_grade, depth_correct, view_filter, seed, frame);
                a.lod = lod_args("trace", lod);
                a.fast = fast;
                PixelTrace traced;
                {
                    nb::gil_scoped_release release;
                    traced = r.trace(a, x, y);
                }
                return trace_dict(std::move(traced));
            },
            nb::arg("R"), nb::arg("t"), nb::arg("fx"), nb::arg("fy"), nb::arg("cx"), nb::arg("cy"), nb::arg("width"),
            nb::arg("height"), nb::arg("near_plane"), nb::arg("projection"), nb::arg("mode"), nb::arg("supersample"),
            nb::arg("sh_degree"), nb::arg("background"), nb::arg("sigma") = 10.0f, nb::arg("weight_background") = 1.0f,
            nb::arg("et_grade") = 4.0f, nb::arg("depth_correct") = false, nb::arg("x") = 0, nb::arg("y") = 0,
            nb::arg("view_filter").none() = nb::none(), nb::arg("lod").none() = nb::none(), nb::arg("seed") = 0,
            nb::arg("frame") = 0, nb::arg("fast") = false,
            "The pixel trace (trace.h) of output pixel (x, y) of this frame.")
        .def("release_buffers", &Renderer::release_buffers, nb::call_guard<nb::gil_scoped_release>(),
             "Free the per-frame buffers and per-camera stages kept for the next frame.")
        .def_prop_ro(
            "buffer_bytes",
            [](const Renderer& r) {
                nb::gil_scoped_release release;  // waits for a running render, whose report may take the GIL
                return r.buffer_bytes();
            },
            "Bytes of the per-frame buffers and per-camera stages kept.");
}
