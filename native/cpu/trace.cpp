// The pixel trace (trace.h): a recorder for the blend's trace hooks, and the driver that blends one pixel's
// sub-samples through blend_tile<Lanes1> with it. Built with the module's baseline flags, like the scalar path.
#include "trace.h"

#include <nanobind/ndarray.h>

#include "frame.h"
#include "trace_dict.h"

#include "../bindings/nb_common.h"

namespace gbv {
namespace {

// The trace of one sub-sample: its records so far and the pixel state after the last one.
struct TraceLog {
    const Splat2D* list;  // the tile's list as blended
    const uint32_t* ids;  // splat id of each entry
    int32_t sample;
    float window[4];
    std::vector<TraceStep>* steps;
    float T = 1.0f, T_cell = 1.0f, total = 1.0f;
    int32_t cell = -1;
    TraceStep& last() { return steps->back(); }
};

// The tracer of gbv/trace.h for one pixel (Lanes1: masks are bool, values float). A tracer is a type, so that renders
// (NoTrace) carry no tracer argument at all; this one records into the calling thread's current log.
struct PixelTracer {
    static constexpr bool records = true;
    static inline thread_local TraceLog* log = nullptr;

    static void skip(bool m, Skip why) {
        if (m && log->last().skip == SKIP_NONE) log->last().skip = why;  // the first failed test is the reason
    }
    static void alpha(bool m, float a) {
        if (m) log->last().alpha = a;
    }
    static void weight(bool m, float w) {
        if (m) log->last().weight = w;
    }
    static void fallback(bool m) {
        if (m) log->last().flags |= TRACE_FALLBACK;
    }
    static void entry(int i, Skip why) {
        TraceStep s = {};
        s.sample = log->sample;
        s.index = (int32_t)log->ids[i];
        s.skip = why;
        s.T_before = s.T_after = log->T;
        for (int k = 0; k < 4; ++k) s.window[k] = log->window[k];
        s.T_cell = log->T_cell;
        s.cell = log->cell;
        s.splat = log->list[i];
        log->steps->push_back(s);
    }
    static void stopped(bool m) {
        if (m) log->last().flags |= TRACE_STOPPED;
    }
    static void after(const AlphaState<Lanes1>& st) { log->T = log->last().T_after = st.T; }
    static void after(const WindowState<Lanes1>& w) {
        const float win[4] = {w.x, w.y, w.w, w.h};
        for (int k = 0; k < 4; ++k) log->window[k] = log->last().window[k] = win[k];
        log->T = log->last().T_after = w.T;
    }
    static void after(const PopfreeState<Lanes1>& st) { log->T = log->last().T_after = st.T; }
    static void after(const DuplexLanes<Lanes1>& d) {
        log->T = log->last().T_after = d.T;
        log->T_cell = log->last().T_cell = d.T_cell;
        log->cell = log->last().cell = d.cell;
    }
    static void resolved(float total) { log->total = total; }
    static void unreached(int from, int n) {
        for (int i = from; i < n; ++i) entry(i, SKIP_DONE);
    }
};

}  // namespace

PixelTrace trace_pixel(const FrameLists& f, int x, int y, int N) {
    const int gx = (f.width + TILE - 1) / TILE;
    PixelTrace out;
    out.samples.resize(N, N, false);
    out.pixel.resize(1, 1, false);
    std::vector<Splat2D> list;
    std::vector<SplatBounds> bounds;
    std::vector<uint32_t> ids;
    std::vector<RaySplat> rays;
    for (int sy = 0; sy < N; ++sy) {
        for (int sx = 0; sx < N; ++sx) {
            const int hx = x * N + sx, hy = y * N + sy;
            const int t = (hy / TILE) * gx + hx / TILE;
            const int64_t begin = f.tile_start[t], count = f.tile_start[t + 1] - begin;
            list.resize(count);
            bounds.resize(count);
            ids.resize(count);
            for (int64_t j = 0; j < count; ++j) {  // as blend_tiles copies a tile's list
                ids[j] = f.ids[begin + j];
                list[j] = f.splats[ids[j]];
                bounds[j] = f.boxes[ids[j]];
            }
            const int tx0 = hx / TILE * TILE, ty0 = hy / TILE * TILE;
            if (f.rays) {
                rays.resize(count);
                for (int64_t j = 0; j < count; ++j) rays[j] = f.rays[ids[j]];
                if (f.mode == STOPTHEPOP && f.queue > 0)
                    cpu::tile_depth_order(*f.cam, tx0, ty0, count, list.data(), bounds.data(), rays.data(), ids.data());
            }
            const size_t q = (size_t)sy * N + sx;
            TileJob job = {};
            job.list = list.data();
            job.bounds = bounds.data();
            job.rays = f.rays ? rays.data() : nullptr;
            job.n = (int)count;
            job.x0 = hx;
            job.y0 = hy;
            job.x1 = hx + 1;
            job.y1 = hy + 1;
            job.width = N;
            job.mode = f.mode;
            job.oit = f.oit;
            job.frame_key = f.frame_key;
            job.planes = f.planes;
            job.queue = f.queue;
            job.tile_x0 = tx0;
            job.tile_y0 = ty0;
            job.fast = f.fast;
            for (int c = 0; c < 3; ++c) job.bg[c] = f.bg[c];
            job.rgb = out.samples.rgb.data() + q * 3;
            job.alpha = out.samples.alpha.data() + q;
            job.window = nullptr;  // the steps hold the window after each entry
            job.evals = out.samples.evals.data() + q;
            // the window a pixel starts with: itself
            TraceLog log = {
                list.data(), ids.data(), (int32_t)q, {(float)hx + 0.5f, (float)hy + 0.5f, 1.0f, 1.0f}, &out.steps};
            PixelTracer::log = &log;
            blend_tile<Lanes1, PixelTracer>(job);
            PixelTracer::log = nullptr;
            out.totals.push_back(log.total);
        }
    }
    box_downsample(out.samples, N, out.pixel);
    return out;
}

nanobind::dict trace_dict(PixelTrace&& tr) {
    namespace nb = nanobind;
    using nbc::to_numpy;
    const size_t n = tr.steps.size();
    std::vector<int32_t> sample(n), index(n), skip(n), flags(n), cell(n);
    std::vector<float> alpha(n), weight(n), T_before(n), T_after(n), T_cell(n), window(n * 4), xy(n * 2), depth(n),
        opacity(n), conic(n * 3), color(n * 3), v1(n * 2), sigma(n * 2), radius(n), log_min_alpha(n);
    for (size_t i = 0; i < n; ++i) {
        const TraceStep& s = tr.steps[i];
        const Splat2D& p = s.splat;
        sample[i] = s.sample;
        index[i] = s.index;
        skip[i] = s.skip;
        flags[i] = s.flags;
        cell[i] = s.cell;
        alpha[i] = s.alpha;
        weight[i] = s.weight;
        T_before[i] = s.T_before;
        T_after[i] = s.T_after;
        T_cell[i] = s.T_cell;
        depth[i] = p.depth;
        opacity[i] = p.opacity;
        radius[i] = p.radius;
        log_min_alpha[i] = p.log_min_alpha;
        for (int k = 0; k < 4; ++k) window[i * 4 + k] = s.window[k];
        for (int k = 0; k < 3; ++k) {
            conic[i * 3 + k] = p.conic[k];
            color[i * 3 + k] = p.color[k];
        }
        const float pairs[3][2] = {{p.xy.x, p.xy.y}, {p.v1.x, p.v1.y}, {p.sigma1, p.sigma2}};
        for (int k = 0; k < 2; ++k) {
            xy[i * 2 + k] = pairs[0][k];
            v1[i * 2 + k] = pairs[1][k];
            sigma[i * 2 + k] = pairs[2][k];
        }
    }
    const size_t S = tr.samples.alpha.size();
    nb::dict d;
    d["sample"] = to_numpy(std::move(sample), {n});
    d["index"] = to_numpy(std::move(index), {n});
    d["skip"] = to_numpy(std::move(skip), {n});
    d["flags"] = to_numpy(std::move(flags), {n});
    d["alpha"] = to_numpy(std::move(alpha), {n});
    d["weight"] = to_numpy(std::move(weight), {n});
    d["T_before"] = to_numpy(std::move(T_before), {n});
    d["T_after"] = to_numpy(std::move(T_after), {n});
    d["window"] = to_numpy(std::move(window), {n, 4});
    d["T_cell"] = to_numpy(std::move(T_cell), {n});
    d["cell"] = to_numpy(std::move(cell), {n});
    d["xy"] = to_numpy(std::move(xy), {n, 2});
    d["depth"] = to_numpy(std::move(depth), {n});
    d["opacity"] = to_numpy(std::move(opacity), {n});
    d["conic"] = to_numpy(std::move(conic), {n, 3});
    d["color"] = to_numpy(std::move(color), {n, 3});
    d["v1"] = to_numpy(std::move(v1), {n, 2});
    d["sigma"] = to_numpy(std::move(sigma), {n, 2});
    d["radius"] = to_numpy(std::move(radius), {n});
    d["log_min_alpha"] = to_numpy(std::move(log_min_alpha), {n});
    d["sample_total"] = to_numpy(std::move(tr.totals), {S});
    d["sample_rgb"] = to_numpy(std::move(tr.samples.rgb), {S, 3});
    d["sample_alpha"] = to_numpy(std::move(tr.samples.alpha), {S});
    d["pixel_rgb"] = to_numpy(std::move(tr.pixel.rgb), {3});
    d["pixel_alpha"] = tr.pixel.alpha[0];
    return d;
}

}  // namespace gbv
