// _native.testing: the CPU renderer's process-wide test and benchmark switches (testing.h) and the exp rate of a
// SIMD path.
#include <nanobind/nanobind.h>
#include <nanobind/stl/string.h>

#include <stdexcept>
#include <string>
#include <vector>

#include "frame.h"
#include "simd.h"
#include "testing.h"

namespace nb = nanobind;
using namespace gbv;

namespace {

// Exp evaluations per second on one core through a SIMD path's exp (the benchmark's reference rate).
double exp_rate(const std::string& path, int64_t n) {
    for (const simd::Path* p : simd::supported()) {
        if (path != p->name) continue;
        nb::gil_scoped_release release;
        cpu::FlushDenormals ftz;
        const cpu::Clock::time_point t0 = cpu::Clock::now();
        volatile float sink = p->exp_sum(n);
        (void)sink;
        return (double)n / (cpu::ms_since(t0) * 1e-3);
    }
    simd::select(path);  // throws the error naming the available paths
    return 0.0;
}

}  // namespace

void bind_testing(nb::module_& m) {
    nb::module_ t = m.def_submodule("testing", "Test and benchmark switches of the CPU renderer (process-wide).");
    t.def(
        "set_pixel_boxes", [](bool on) { cpu::testing::pixel_boxes.store(on); }, nb::arg("on"),
        "Skip lane groups outside a splat's pixel box (default) or evaluate every list entry.");
    t.def(
        "set_row_bands", [](bool on) { cpu::testing::row_bands.store(on); }, nb::arg("on"),
        "Lane groups walk their row's band of the tile list where that saves work (default) or the whole list.");
    t.def(
        "set_gaussian_band_margin",
        [](float px) {
            if (!(px >= 0.0f && px <= 16.0f)) throw std::invalid_argument("the band margin must be in [0, 16] px");
            cpu::testing::gaussian_band_margin.store(px);
        },
        nb::arg("px"),
        "How far (px, 0 ... 16) gaussian_blending's row bands reach about the row's pixel centres "
        "(default 2).");
    t.def(
        "set_cut_flat_above", [](int64_t n) { cpu::testing::cut_flat_above.store(n); }, nb::arg("n"),
        "The level-of-detail cut walks top down; it evaluates every node instead once a level reaches more than n "
        "nodes, a quarter of it, and most of them open on (default 65536; 0: every node of any tree).");
    t.def(
        "set_cut_stop_after", [](int64_t n) { cpu::testing::cut_stop_after.store(n); }, nb::arg("n"),
        "lod.cut stops, as if cancelled, once it has asked its stop n times (-1: never, the default).");
    t.def(
        "set_poison_images", [](bool on) { cpu::testing::poison_images.store(on); }, nb::arg("on"),
        "Fill each new image with NaN (evaluation counts -1) before the blend (to show it writes every pixel).");
    t.def(
        "set_capture_preprocess", [](bool on) { cpu::testing::capture.store(on); }, nb::arg("on"),
        "Keep the next renders' preprocess output and tile lists for captured_preprocess() and captured_lists().");
    t.def(
        "captured_preprocess",
        [] {
            const std::vector<uint8_t> v = cpu::testing::captured_preprocess();
            return nb::bytes(reinterpret_cast<const char*>(v.data()), v.size());
        },
        "The last captured frame's preprocess: per splat the valid byte, then its Splat2D and TileRect (zeros when "
        "culled).");
    t.def(
        "captured_lists",
        [] {
            const auto [starts, keys] = cpu::testing::captured_lists();
            return nb::make_tuple(nb::bytes(reinterpret_cast<const char*>(starts.data()), starts.size() * 8),
                                  nb::bytes(reinterpret_cast<const char*>(keys.data()), keys.size() * 8));
        },
        "The last captured frame's tile lists: (tile_start int64 (tiles + 1), keys uint64 (depth bits << 32 | "
        "splat id; duplex: the splat id)).");
    t.def("half_mismatches", &cpu::testing::half_mismatches, nb::arg("begin"), nb::arg("end"),
          nb::call_guard<nb::gil_scoped_release>(),
          "How many float bit patterns in [begin, end) (multiples of 4) the float16 conversion of the scene loader "
          "converts otherwise than the F16C instruction; -1 without F16C.");
    t.def(
        "set_simd", [](const std::string& name) { simd::select(name); }, nb::arg("name"),
        "Use this SIMD path for later renders (scalar, avx2, avx512).");
    t.def("exp_rate", &exp_rate, nb::arg("path"), nb::arg("n"),
          "Exp evaluations per second on one core through the path's vector exp.");
}
