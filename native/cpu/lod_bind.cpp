// gbviewer._native.lod: the splat hierarchy's build, cut and gather (lod.h) for gbviewer.lod.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>

#include "omp_shim.h"

#include <atomic>
#include <cstring>
#include <memory>
#include <optional>

#include "../bindings/nb_common.h"
#include "lod.h"
#include "lod_args.h"
#include "testing.h"

namespace nb = nanobind;
using namespace gbv::nbc;
using LArr = L64;

namespace gbv {
namespace {

nb::dict build(FArr means, FArr scales, FArr quats, FArr opacities, FArr sh, std::optional<FArr> filter, int rule,
               int threads) {
    const int64_t n = check_scene("lod build", means, scales, quats, opacities, sh, filter);
    if (rule < lod::DEPTH || rule > lod::OPACITY_WEIGHTS)
        fail("lod build", "rule must be 0 (depth), 1 (sum) or 2 (opacity weights)");
    const int k = (int)sh.shape(1);
    const lod::Splats s{means.data(),
                        scales.data(),
                        quats.data(),
                        opacities.data(),
                        sh.data(),
                        filter ? filter->data() : nullptr,
                        n,
                        k};
    lod::Tree t;
    {
        nb::gil_scoped_release release;
        t = lod::build(s, (lod::OpacityRule)rule, threads);
    }
    const size_t m = t.opacities.size(), levels = t.levels.size();
    nb::dict d;
    d["order"] = to_numpy(std::move(t.order), {(size_t)n});
    d["levels"] = to_numpy(std::move(t.levels), {levels});
    d["means"] = to_numpy(std::move(t.means), {m, 3});
    d["scales"] = to_numpy(std::move(t.scales), {m, 3});
    d["quats"] = to_numpy(std::move(t.quats), {m, 4});
    d["opacities"] = to_numpy(std::move(t.opacities), {m});
    d["sh"] = to_numpy(std::move(t.sh), {m, (size_t)k, 3});
    d["radius"] = to_numpy(std::move(t.radius), {m});
    d["size"] = to_numpy(std::move(t.size), {m});
    if (filter) d["filter_3d"] = to_numpy(std::move(t.filter), {m});
    return d;
}

nb::object cut(FArr means, FArr radius, FArr size, LArr levels, IArr order, FArr eye, double focal, bool orthographic,
               double tau, double band, int threads, std::optional<LArr> cancel) {
    const size_t L = levels.shape(0);
    if (L < 2 || eye.size() != 3) fail("lod cut", "levels must hold at least 2 offsets, eye 3 floats");
    const int64_t n = levels.data()[1], m = check_levels("lod cut", levels, n);
    if (order.size() != (size_t)n || means.size() != (size_t)m * 3 || radius.size() != (size_t)m ||
        size.size() != (size_t)m || n + m > INT32_MAX)
        fail("lod cut", "array shapes do not match the levels");
    if (cancel && cancel->shape(0) < 1) fail("lod cut", "cancel must hold at least one int64");
    const lod::View v{{eye.data()[0], eye.data()[1], eye.data()[2]}, focal, orthographic};
    const int64_t* flag = cancel ? cancel->data() : nullptr;
    const int64_t stop_after = cpu::testing::cut_stop_after.load(std::memory_order_relaxed);
    std::atomic<int64_t> asks{0};
    const auto stop = [flag, stop_after, &asks] {
        return (flag && __atomic_load_n(flag, __ATOMIC_RELAXED) != 0) ||
               (stop_after >= 0 && asks.fetch_add(1, std::memory_order_relaxed) >= stop_after);
    };
    lod::Cut c;
    {
        nb::gil_scoped_release release;
        c = lod::cut(means.data(), radius.data(), size.data(), levels.data(), (int)L, order.data(), v, tau, band, 0,
                     threads, stop);
    }
    if (c.stopped) return nb::none();
    const size_t rows = c.rows.size();
    return nb::make_tuple(to_numpy(std::move(c.rows), {rows}), to_numpy(std::move(c.weights), {rows}), c.leaves);
}

// Rows `leaves` of a then `nodes` of b, `width` floats each, into a new (len, width) array.
nb::ndarray<nb::numpy, float> rows(const FArr& a, const FArr& b, const IArr& leaves, const IArr& nodes, size_t width,
                                   std::initializer_list<size_t> tail, int nt) {
    const int64_t nl = (int64_t)leaves.size(), ni = (int64_t)nodes.size();
    if (a.size() % width || b.size() % width) fail("lod gather", "row widths of the leaf and node arrays differ");
    const int64_t na = (int64_t)(a.size() / width), nb_ = (int64_t)(b.size() / width);
    std::unique_ptr<float[]> out(new float[(size_t)(nl + ni) * width]);  // written once, in parallel (first touch)
    bool bad = false;
#pragma omp parallel for num_threads(nt) schedule(static, 1024) reduction(|| : bad)
    for (int64_t r = 0; r < nl + ni; ++r) {
        const int64_t i = r < nl ? leaves.data()[r] : nodes.data()[r - nl];
        if (i < 0 || i >= (r < nl ? na : nb_)) {
            bad = true;
            continue;
        }
        const float* src = (r < nl ? a.data() : b.data()) + (size_t)i * width;
        std::memcpy(&out[(size_t)r * width], src, width * sizeof(float));
    }
    if (bad) fail("lod gather", "an index outside its array");
    std::vector<size_t> shape{(size_t)(nl + ni)};
    shape.insert(shape.end(), tail);
    float* data = out.release();
    nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<float*>(p); });
    return nb::ndarray<nb::numpy, float>(data, shape.size(), shape.data(), owner);
}

// The cut's splats: leaves first (scene rows), then interior nodes (tree rows); opacities times the weights.
nb::dict gather(nb::dict scene, nb::dict tree, IArr leaves, FArr leaf_w, IArr nodes, FArr node_w, int threads) {
    if (leaf_w.size() != leaves.size() || node_w.size() != nodes.size())
        fail("lod gather", "one weight per index expected");
    const int nt = gbv::team(threads);
    nb::dict d;
    auto arr = [](nb::dict& src, const char* name) { return nb::cast<FArr>(src[name]); };
    const std::pair<const char*, size_t> fields[] = {{"means", 3}, {"scales", 3}, {"quats", 4}, {"opacities", 1}};
    for (const auto& [name, width] : fields)
        d[name] = rows(arr(scene, name), arr(tree, name), leaves, nodes, width,
                       width > 1 ? std::initializer_list<size_t>{width} : std::initializer_list<size_t>{}, nt);
    for (const char* name : {"sh", "filter_3d"}) {
        if (!scene.contains(name)) continue;
        const FArr a = arr(scene, name);
        const size_t width = a.ndim() == 3 ? a.shape(1) * 3 : 1;
        d[name] = a.ndim() == 3 ? rows(a, arr(tree, name), leaves, nodes, width, {a.shape(1), 3}, nt)
                                : rows(a, arr(tree, name), leaves, nodes, 1, {}, nt);
    }
    auto op = nb::cast<nb::ndarray<float, nb::c_contig, nb::device::cpu>>(d["opacities"]);
    const int64_t nl = (int64_t)leaves.size(), total = nl + (int64_t)nodes.size();
    float* o = op.data();
#pragma omp parallel for num_threads(nt) schedule(static)
    for (int64_t r = 0; r < total; ++r) o[r] *= r < nl ? leaf_w.data()[r] : node_w.data()[r - nl];
    return d;
}

}  // namespace

void bind_lod(nb::module_& m) {
    nb::module_ l = m.def_submodule("lod", "Level of detail: the splat hierarchy, its cut per camera, the gather.");
    l.def("build", &build, nb::arg("means"), nb::arg("scales"), nb::arg("quats"), nb::arg("opacities"), nb::arg("sh"),
          nb::arg("filter_3d").none(), nb::arg("rule"), nb::arg("threads"),
          "The hierarchy's arrays: order, levels, and per interior node means, scales, quats, opacities, sh, "
          "radius, size (filter_3d with one).");
    l.def("cut", &cut, nb::arg("means"), nb::arg("radius"), nb::arg("size"), nb::arg("levels"), nb::arg("order"),
          nb::arg("eye"), nb::arg("focal"), nb::arg("orthographic"), nb::arg("tau"), nb::arg("band"),
          nb::arg("threads"), nb::arg("cancel").none() = nb::none(),
          "(rows, weights, leaves) drawn for the view: the first `leaves` rows are splats, the rest interior nodes; "
          "None once cancel[0] is nonzero (the cut stopped early).");
    l.def("gather", &gather, nb::arg("scene"), nb::arg("tree"), nb::arg("leaves"), nb::arg("leaf_weights"),
          nb::arg("nodes"), nb::arg("node_weights"), nb::arg("threads"),
          "The cut's splat arrays (dict of scene and tree arrays in; means ... opacities times weights out).");
}

}  // namespace gbv
