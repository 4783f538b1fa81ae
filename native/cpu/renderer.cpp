// The CPU renderer (renderer.h): the uploaded scene, the per-frame buffers, and one frame at a time.
#include "renderer.h"
#include "testing.h"

#include <algorithm>
#include <mutex>
#include <stdexcept>
#include <string>
#include <utility>

#include "frame.h"

namespace gbv::cpu {

struct Renderer::Impl {
    mutable std::mutex mutex;  // serialises every method
    SceneView scene;
    std::shared_ptr<const void> scene_owner, weights_owner, cells_owner;  // keep the caller's arrays alive
    std::atomic<int64_t> n{0};
    FrameBuffers buffers;

    // Drop the owners under the lock, release them after it (an owner's deleter may take the Python GIL, which a
    // render's progress report takes while the lock is held).
    std::vector<std::shared_ptr<const void>> forget_cells() {
        scene.cell_means = scene.cell_scales = scene.cell_quats = nullptr;
        scene.cell_offsets = scene.cell_members = nullptr;
        scene.m = 0;
        scene.cell_of.clear();
        return {std::move(cells_owner)};
    }
};

Renderer::Renderer() : impl_(std::make_unique<Impl>()) {}
Renderer::~Renderer() = default;

void Renderer::upload(const float* means, const float* scales, const float* quats, const float* opacities,
                      const float* sh, const float* filter_3d, int64_t n, int k, std::shared_ptr<const void> owner) {
    std::vector<std::shared_ptr<const void>> old;
    {
        std::lock_guard<std::mutex> lock(impl_->mutex);
        old = impl_->forget_cells();
        old.push_back(std::move(impl_->weights_owner));
        old.push_back(std::move(impl_->scene_owner));
        SceneView& sc = impl_->scene;
        sc.means = means;
        sc.scales = scales;
        sc.quats = quats;
        sc.opacities = opacities;
        sc.sh = sh;
        sc.filter_3d = filter_3d;
        sc.n = n;
        sc.k = k;
        sc.weight_sh = nullptr;
        sc.weight_k = 0;
        impl_->scene_owner = std::move(owner);
        impl_->n.store(n);
    }
}

int64_t Renderer::num_splats() const { return impl_->n.load(); }

void Renderer::upload_weights(const float* weight_sh, int64_t n, int weight_k, std::shared_ptr<const void> owner) {
    std::shared_ptr<const void> old;
    std::lock_guard<std::mutex> lock(impl_->mutex);
    if (n != impl_->scene.n) throw std::invalid_argument("upload_weights: weight_sh must have the scene's N rows");
    impl_->scene.weight_sh = weight_sh;
    impl_->scene.weight_k = weight_k;
    old = std::exchange(impl_->weights_owner, std::move(owner));
}

void Renderer::upload_cells(const float* means, const float* scales, const float* quats, const int32_t* offsets,
                            const int32_t* members, const int32_t* cell_of, int64_t num_cells, int64_t num_members,
                            std::shared_ptr<const void> owner) {
    (void)num_members;
    std::vector<std::shared_ptr<const void>> old;
    std::lock_guard<std::mutex> lock(impl_->mutex);
    old = impl_->forget_cells();
    SceneView& sc = impl_->scene;
    sc.cell_of.assign(cell_of, cell_of + sc.n);
    sc.cell_means = means;
    sc.cell_scales = scales;
    sc.cell_quats = quats;
    sc.cell_offsets = offsets;
    sc.cell_members = members;
    sc.m = num_cells;
    impl_->cells_owner = std::move(owner);
}

namespace {

// omp_set_num_threads for the scope (0: unchanged).
struct ThreadCount {
    int prev = omp_get_max_threads(), threads;
    explicit ThreadCount(int t) : threads(t) {
        if (threads > 0) omp_set_num_threads(threads);
    }
    ~ThreadCount() {
        if (threads > 0) omp_set_num_threads(prev);
    }
};

int sh_degree_of(const RenderArgs& a, const SceneView& sc) {
    return std::max(0, std::min(a.sh_degree, sh_degree_for_coeffs(sc.k)));
}

void check_cells(const RenderArgs& a, const SceneView& sc, const char* where) {
    if (a.mode == DUPLEX && sc.cell_of.size() != (size_t)sc.n)
        throw std::invalid_argument(std::string(where) + ": duplex needs the scene's cells (upload_cells)");
}

}  // namespace

RenderResult Renderer::render(const RenderArgs& a, const Control& control) {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    const SceneView& sc = impl_->scene;
    check_cells(a, sc, "render");
    RenderResult res;
    const simd::Path& path = simd::current();  // the one this frame runs and reports, whatever set_simd does meanwhile
    res.simd = path.name;
    const bool window = a.want_window && a.mode == GAUSSIAN_BLENDING;
    const int N = a.supersample;
    const int sh_deg = sh_degree_of(a, sc);
    FrameRun run(control);
    ThreadCount threads(control.threads);
    const bool poison = testing::poison_images.load(std::memory_order_relaxed);
    res.image.resize(a.width, a.height, window, poison);
    if (N == 1) {
        render_image(sc, a.cam, a.mode, a.oit, sh_deg, a.bg, path, impl_->buffers, res.image, res.stats, run, 1);
    } else {
        Image hi;
        hi.resize(a.width * N, a.height * N, window, poison);
        render_image(sc, a.cam, a.mode, a.oit, sh_deg, a.bg, path, impl_->buffers, hi, res.stats, run, N);
        const Clock::time_point t0 = Clock::now();
        if (!run.cancelled()) box_downsample(hi, N, res.image);
        res.stats.blend_ms += ms_since(t0);
    }
    if (!run.cancelled()) run.report();  // the last count
    res.cancelled = run.cancelled();
    res.stopped = run.stopped();
    return res;
}

PixelTrace Renderer::trace(const RenderArgs& a, int x, int y) {
    if (!(x >= 0 && x < a.width && y >= 0 && y < a.height))
        throw std::invalid_argument("trace: pixel outside the image");
    std::lock_guard<std::mutex> lock(impl_->mutex);
    const SceneView& sc = impl_->scene;
    check_cells(a, sc, "trace");
    return trace_frame_pixel(sc, a.cam, a.mode, a.oit, sh_degree_of(a, sc), a.bg, simd::current(), impl_->buffers, x,
                             y, a.supersample);
}

void Renderer::release_buffers() {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->buffers = FrameBuffers();
}

size_t Renderer::buffer_bytes() const {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    const FrameBuffers& b = impl_->buffers;
    return b.splats.capacity() * sizeof(Splat2D) + b.rects.capacity() * sizeof(TileRect) + b.valid.capacity() +
           b.tile_start.capacity() * sizeof(int64_t) + b.keys.capacity() * sizeof(uint64_t) +
           (b.order.capacity() + b.order_scratch.capacity()) * sizeof(uint64_t) +
           b.boxes.capacity() * sizeof(SplatBounds);
}

}  // namespace gbv::cpu
