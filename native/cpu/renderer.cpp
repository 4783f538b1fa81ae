// The CPU renderer (renderer.h): the uploaded scene, the per-frame buffers and stages, and the frames of a call.
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
    std::shared_ptr<const void> scene_owner, weights_owner, cells_owner, lod_owner;  // keep the caller's arrays alive
    std::atomic<int64_t> n{0};
    uint64_t generation = 0;  // of the uploaded scene, weights and cells (StageKey::scene)
    std::vector<Stage> stages;  // the last call's, one per distinct key
    std::vector<FrameBuffers> buffers;  // the last call's, one per frame

    // The stages of `keys` (distinct): a cached one reused where its key matches and it is ready, the others built
    // in the storage of those left over (a new one where none is); what no key needs is freed.
    std::vector<Stage> take_stages(const std::vector<StageKey>& keys) {
        std::vector<Stage> out(keys.size());
        std::vector<bool> found(keys.size(), false);
        for (size_t k = 0; k < keys.size(); ++k) {
            for (Stage& s : stages) {
                if (s.ready && s.key == keys[k]) {
                    out[k] = std::move(s);
                    s = Stage();
                    found[k] = true;
                    break;
                }
            }
        }
        size_t spare = 0;
        for (size_t k = 0; k < keys.size(); ++k) {
            if (found[k]) continue;
            while (spare < stages.size() && stages[spare].splats.capacity() == 0) ++spare;
            if (spare < stages.size()) out[k] = std::move(stages[spare++]);
            out[k].ready = false;
        }
        stages.clear();
        return out;
    }

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
        old.push_back(std::move(impl_->lod_owner));
        SceneView& sc = impl_->scene;
        sc.tree = {};
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
        ++impl_->generation;
        impl_->scene_owner = std::move(owner);
        impl_->n.store(n);
    }
}

int64_t Renderer::num_splats() const { return impl_->n.load(); }

std::pair<int, bool> Renderer::scene_layout() const {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    return {impl_->scene.k, impl_->scene.filter_3d != nullptr};
}

void Renderer::upload_lod(const float* means, const float* scales, const float* quats, const float* opacities,
                          const float* sh, int k, const float* filter_3d, const float* radius, const float* size,
                          const int64_t* levels, int num_levels, const int32_t* order,
                          std::shared_ptr<const void> owner) {
    std::shared_ptr<const void> old;
    std::lock_guard<std::mutex> lock(impl_->mutex);
    const SceneView& sc = impl_->scene;  // checked again here: a concurrent upload may have replaced the scene
    if (num_levels < 2 || levels[1] != sc.n || k != sc.k || (filter_3d != nullptr) != (sc.filter_3d != nullptr))
        throw std::invalid_argument("upload_lod: the hierarchy is not of the uploaded scene");
    impl_->scene.tree = {means, scales, quats, opacities, sh, filter_3d, radius, size, levels, order, num_levels};
    ++impl_->generation;
    old = std::exchange(impl_->lod_owner, std::move(owner));
}

void Renderer::upload_weights(const float* weight_sh, int64_t n, int weight_k, std::shared_ptr<const void> owner) {
    std::shared_ptr<const void> old;
    std::lock_guard<std::mutex> lock(impl_->mutex);
    if (n != impl_->scene.n) throw std::invalid_argument("upload_weights: weight_sh must have the scene's N rows");
    impl_->scene.weight_sh = weight_sh;
    impl_->scene.weight_k = weight_k;
    ++impl_->generation;
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
    ++impl_->generation;
    impl_->cells_owner = std::move(owner);
}

namespace {

// omp_set_num_threads for the scope: `team(t)` (0: OpenMP's default, capped at MAX_TEAM), unchanged where it is so.
struct ThreadCount {
    int prev = omp_get_max_threads(), threads;
    explicit ThreadCount(int t) : threads(team(t)) {
        if (threads != prev) omp_set_num_threads(threads);
    }
    ~ThreadCount() {
        if (threads != prev) omp_set_num_threads(prev);
    }
};

int sh_degree_of(const RenderArgs& a, const SceneView& sc) {
    return std::max(0, std::min(a.sh_degree, sh_degree_for_coeffs(sc.k)));
}

// What a frame needs uploaded: duplex its cells; level of detail the hierarchy, and no per-splat data the finish
// would index by the cut's splats (duplex's cells, wsr's view weights; cells uploaded for a duplex frame of the
// same scene are not read by the other modes).
void check_uploads(const RenderArgs& a, const SceneView& sc, const char* where) {
    if (a.rw && a.mode == DUPLEX)
        throw std::invalid_argument(std::string(where) +
                                    ": duplex renders whole images only (its cells cull by "
                                    "the image's tiles)");
    if (a.mode == DUPLEX && sc.cell_of.size() != (size_t)sc.n)
        throw std::invalid_argument(std::string(where) + ": duplex needs the scene's cells (upload_cells)");
    if (!a.lod.on()) return;
    if (sc.tree.num_levels < 2)
        throw std::invalid_argument(std::string(where) + ": level of detail needs the scene's hierarchy (upload_lod)");
    if (a.mode == DUPLEX || (a.mode == WSR && sc.weight_sh))
        throw std::invalid_argument(std::string(where) +
                                    ": level of detail is for plain splat scenes, not duplex "
                                    "or wsr with view weights");
}

// The part of the stage camera's image a frame renders (RenderArgs::rx .. rh at its supersampled resolution).
TileRegion region_of(const RenderArgs& a) {
    if (a.rw == 0) return TileRegion::whole(a.cam);
    const int N = a.supersample;
    return {a.rx * N, a.ry * N, (a.rx + a.rw) * N, (a.ry + a.rh) * N};
}

// The StageKey of a frame: everything its stage depends on (add a field here and to StageKey::operator==).
StageKey stage_key(const RenderArgs& a, const SceneView& sc, uint64_t generation) {
    return StageKey{generation,
                    a.cam,
                    sh_degree_of(a, sc),
                    stage_reach(a.mode, a.oit),
                    a.lod.on() ? a.lod : LodArgs{},
                    stage_rules(a.mode, a.oit)};
}

}  // namespace

RenderResult Renderer::render(const RenderArgs& a, const Control& control) {
    return std::move(render_many({a}, control)[0]);
}

std::vector<RenderResult> Renderer::render_many(const std::vector<RenderArgs>& frames, const Control& control) {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    const SceneView& sc = impl_->scene;
    for (const RenderArgs& a : frames) check_uploads(a, sc, "render");
    const int count = (int)frames.size();
    const simd::Path& path = simd::current();  // the one these frames run and report, whatever set_simd does meanwhile
    FrameRun run(control, count);
    ThreadCount threads(control.threads);
    std::vector<StageKey> keys;
    std::vector<int> stage_of(count);
    for (int f = 0; f < count; ++f) {
        const RenderArgs& a = frames[f];
        const StageKey key = stage_key(a, sc, impl_->generation);
        stage_of[f] = (int)(std::find(keys.begin(), keys.end(), key) - keys.begin());
        if (stage_of[f] == (int)keys.size()) keys.push_back(key);
        const TileRegion reg = region_of(a);
        run.start(f, (int64_t)reg.gx() * reg.gy());
    }
    std::vector<Stage> stages = impl_->take_stages(keys);
    impl_->buffers.resize(count);  // the per-frame buffers of frames beyond this call's are freed
    std::vector<RenderResult> res(count);
    std::vector<Image> hi(count);  // supersampled frames' images at the camera's resolution
    const bool poison = testing::poison_images.load(std::memory_order_relaxed);
    for (int f = 0; f < count; ++f) {
        const RenderArgs& a = frames[f];
        const bool window = a.want_window && a.mode == GAUSSIAN_BLENDING;
        const int w = a.rw ? a.rw : a.width, h = a.rw ? a.rh : a.height;
        res[f].image.resize(w, h, window, poison);
        if (a.supersample > 1) hi[f].resize(w * a.supersample, h * a.supersample, window, poison);
    }
    std::vector<BlendFrame> blend;
    for (int f = 0; f < count && !run.cancelled(); ++f) {
        const RenderArgs& a = frames[f];
        RenderResult& r = res[f];
        Stage& stage = stages[stage_of[f]];
        r.stats.stage_reused = stage.ready;
        if (!stage.ready) build_stage(sc, keys[stage_of[f]], path, stage, r.stats, run);
        if (run.cancelled()) break;
        const TileRegion reg = region_of(a);
        bin_frame(sc, stage, a.mode, a.oit, path, impl_->buffers[f], r.stats, run, reg);
        Image* img = a.supersample > 1 ? &hi[f] : &r.image;
        blend.push_back({&impl_->buffers[f], &stage.key.cam, a.mode, a.oit, a.queue, a.bg, img, a.supersample, &r.stats,
                         stochastic_frame_key(a.seed, a.frame), reg, a.fast});
    }
    if (!run.cancelled()) blend_frames(blend, path.blend_tile, run);
    for (int f = 0; f < count; ++f) {
        if (frames[f].supersample == 1 || run.cancelled()) continue;
        const Clock::time_point t0 = Clock::now();
        box_downsample(hi[f], frames[f].supersample, res[f].image);
        res[f].stats.blend_ms += ms_since(t0);
    }
    if (!run.cancelled()) run.report();  // the last counts
    for (int f = 0; f < count; ++f) {
        RenderResult& r = res[f];
        // the per-pixel sorted modes blend one pixel at a time on every path (blend_one_tile): their blend ran scalar
        r.simd = per_pixel_sorted(frames[f].mode) ? "scalar" : path.name;
        r.cancelled = run.cancelled();
        r.stopped = run.stopped();
    }
    impl_->stages = std::move(stages);
    return res;
}

PixelTrace Renderer::trace(const RenderArgs& a, int x, int y) {
    if (!(x >= 0 && x < a.width && y >= 0 && y < a.height))
        throw std::invalid_argument("trace: pixel outside the image");
    std::lock_guard<std::mutex> lock(impl_->mutex);
    const SceneView& sc = impl_->scene;
    check_uploads(a, sc, "trace");
    ThreadCount threads(0);  // the stage it may build runs parallel regions: OpenMP's default team, capped
    const simd::Path& path = simd::current();
    const StageKey key = stage_key(a, sc, impl_->generation);
    std::vector<Stage> stages = impl_->take_stages({key});
    if (!stages[0].ready) {
        Stats st;
        const Control none;
        FrameRun run(none, 1);
        build_stage(sc, key, path, stages[0], st, run);
    }
    impl_->buffers.resize(1);
    PixelTrace t = trace_frame_pixel(sc, stages[0], a.mode, a.oit, a.queue, stochastic_frame_key(a.seed, a.frame),
                                     a.fast, a.bg, path, impl_->buffers[0], x, y, a.supersample);
    const Plane<int32_t>& rows = stages[0].rows;  // a level-of-detail cut drawn in place: entry i is row rows[i]
    if (!rows.empty())
        for (TraceStep& s : t.steps) s.index = rows[s.index];  // the scene's splat, or n + an interior node's index
    impl_->stages = std::move(stages);
    return t;
}

void Renderer::release_buffers() {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->buffers.clear();
    impl_->buffers.shrink_to_fit();
    impl_->stages.clear();
    impl_->stages.shrink_to_fit();
}

size_t Renderer::buffer_bytes() const {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    size_t bytes = 0;
    for (const FrameBuffers& b : impl_->buffers)
        bytes += b.splats.capacity() * sizeof(Splat2D) + b.rects.capacity() * sizeof(TileRect) + b.valid.capacity() +
                 b.tile_start.capacity() * sizeof(int64_t) + b.ids.capacity() * sizeof(uint32_t) +
                 b.boxes.capacity() * sizeof(SplatBounds) + b.planes.capacity() * sizeof(DepthPlane);
    for (const Stage& s : impl_->stages) bytes += s.bytes();
    return bytes;
}

}  // namespace gbv::cpu
