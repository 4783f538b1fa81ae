// What a tile's blend reads (TileJob: the tile's list, the boxes its splats can change, row bands, the image planes)
// and the walk of a lane group over the list (tile::walk): the plain-data interface that blend_tile.h's groups, the
// vector paths' translation units and the pixel trace share.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>
#include <vector>

#include "gbv/blend.h"
#include "gbv/popfree.h"
#include "gbv/ray3d.h"

namespace gbv {

namespace tile {
struct HierCache;
}

// Box of pixel centres a splat can change in its mode: outside it the splat is skipped without evaluating it (an
// exact test, with margin for float rounding; see splat_bounds in frame.cpp). Infinite where no such box is known.
struct SplatBounds {
    float x0, x1, y0, y1;
};

// gaussian_blending's SplatBounds: the window centres that can pass blend_gaussian's cut-off, before the group box
// adds the lanes' half perimeters. A lane passes only if the point of its window box (lu x lv about the window centre
// in the splat's eigen-frame) nearest the splat centre has (u is1)^2 + (v is2)^2 <= r2 = -2 log_min_alpha, i.e. lies
// in the ellipse E whose screen bounding box has half sides sqrt(r2 (v1x^2 / is1^2 + v1y^2 / is2^2)) and
// sqrt(r2 (v1y^2 / is1^2 + v1x^2 / is2^2)); that point is within half the window's diagonal <= half its perimeter
// (w + h) / 2 of the centre. So the centre lies in E's box grown by the half perimeter, and (the reach test) within
// radius + half perimeter of the splat centre: the box is the tighter of E's box and the radius square, in double,
// widened for the lane's float rounding (1e-5 of the larger half side: r2's and the offsets' few ulp, in either
// direction for a thin splat; plus 0.01 px and 1e-6 of the coordinates; the group box adds its own 1e-3 and 1e-6). Empty when opacity < min alpha (r2 < 0); the
// radius square where a field is not finite (a NaN in the lane's test passes it).
inline SplatBounds gaussian_blending_bounds(const Splat2D& s) {
    constexpr float inf = std::numeric_limits<float>::infinity();
    const double pos = 0.01 + 1e-6 * (fabs(s.xy.x) + fabs(s.xy.y));
    double ex = (double)s.radius * (1.0 + 1e-6) + pos, ey = ex;
    const double r2 = -2.0 * (double)s.log_min_alpha;
    if (r2 < 0.0) return {inf, -inf, inf, -inf};
    const double a = 1.0 / (double)s.inv_sigma1, b = 1.0 / (double)s.inv_sigma2;
    const double vx = s.v1.x, vy = s.v1.y;
    const double tx0 = std::sqrt(r2 * (vx * vx * a * a + vy * vy * b * b));
    const double ty0 = std::sqrt(r2 * (vy * vy * a * a + vx * vx * b * b));
    const double grow = 1e-5 * std::max(tx0, ty0) + pos;  // offsets round by ~4 ulp of |d| <= the larger half side
    const double tx = tx0 + grow, ty = ty0 + grow;
    if (std::isfinite(tx) && std::isfinite(ty)) {
        ex = std::min(ex, tx);
        ey = std::min(ey, ty);
    }
    return {(float)(s.xy.x - ex), (float)(s.xy.x + ex), (float)(s.xy.y - ey), (float)(s.xy.y + ey)};
}

// Row bands of a tile's list: for each pixel row of the tile, the list entries whose SplatBounds meet the band
// [yc - margin, yc + margin] about the row's pixel centre yc, in list order (build_bands, blend_bands.h). A lane group
// of that row whose box lies inside the band can walk the band instead of the whole list: every other entry's bounds
// miss the box in y, so the walk's `outside` test would skip it anyway.
struct Bands {
    float lo[TILE], hi[TILE];  // row r's band
    int64_t start[TILE + 1];  // row r's entries: idx[start[r] .. start[r + 1])
    std::vector<int32_t> idx;
    std::vector<int8_t> first, last;  // each entry's rows first .. last (none when last < first)
};

struct TileJob {
    const Splat2D* list;  // the tile's splats in blend order
    const SplatBounds* bounds;  // one per list entry
    int n;
    int x0, y0, x1, y1;  // pixel rectangle [x0, x1) x [y0, y1)
    int width;  // row stride of the planes in pixels
    Mode mode;
    OitParams oit;
    int queue;  // stopthepop's K (0: unbounded)
    int tile_x0, tile_y0;  // the tile's first pixel (stopthepop's sub-tiles), whatever rectangle is blended
    tile::HierCache* hier;  // stopthepop:K: the tile's 2x2 streams (blend_sorted.h), or null: each pixel walks alone
    float bg[3];
    float *rgb, *alpha, *window;  // image planes, at the rectangle's pixel (x0, y0); window may be null
    int32_t* evals;
    const Bands* bands;  // the list's row bands, or null: every group walks the whole list
    uint32_t frame_key;  // stochastic: stochastic_frame_key(seed, frame)
    const DepthPlane* planes;  // stochastic_popfree: per splat (Splat2D::id), else null
    const RaySplat* rays;  // eval3d, stopthepop: one per list entry (ray3d.h), else null
    bool fast = false;  // gaussian_blending at the fast precision (blend_gaussian's Fast)
    int group_rows = 1;  // pixel rows per lane group and per band (FAST_GB_GROUP_ROWS: a vector path, fast GB)
};

// Pixel rows per lane group of a vector path's fast gaussian_blending: a square group of 16 lanes (4 x 4) meets a
// small splat in more of its lanes, and fewer groups meet it, than one row of 16 pixels does.
constexpr int FAST_GB_GROUP_ROWS = 4;

using BlendTileFn = void (*)(const TileJob&);
void blend_tile_scalar(const TileJob& job);  // the scalar path's (blend_scalar.cpp)

namespace tile {

// The list entries a group visits, in order: its row's band while the group's box lies inside the band [lo, hi],
// then (once a moving window leaves it) the whole list on from the last entry visited; or the whole list.
struct Cursor {
    const int32_t* band;  // null: the whole list
    int band_n;
    float lo, hi;
    int j = 0, i = -1;
    // The next entry, -1 after the last; [ya, yb]: the group's box now.
    int next(int n, float ya, float yb) {
        if (band && !(ya >= lo && yb <= hi)) band = nullptr;
        if (band) return j < band_n ? (i = band[j++]) : -1;
        return ++i < n ? i : -1;
    }
};

static inline bool outside(const SplatBounds& b, float xa, float xb, float ya, float yb) {
    return yb < b.y0 || ya > b.y1 || xb < b.x0 || xa > b.x1;
}

struct Box {  // a group box: [xa, xb] x [ya, yb]
    float xa, xb, ya, yb;
};

// The entries of a Cursor whose SplatBounds meet a group box, tested CHUNK at a time without a branch per entry
// (gaussian_blending's groups skip most entries of their long lists). When the box changes (its windows moved) the
// rest of the chunk is tested again, and a box that left the cursor's band sends it to the whole list after the last
// entry returned, as Cursor::next would: the same entries come back in the same order as testing each against the
// box of the moment.
struct Filtered {
    static constexpr int CHUNK = 32;
    Cursor src;
    Box box{};
    int idx[CHUNK];  // the chunk's entries
    int n = 0, at = 0, last = -1;  // entries in the chunk, the position after the last returned, that entry
    uint32_t hits = 0;  // chunk positions >= at that meet `box`

    explicit Filtered(const Cursor& c) : src(c) {}

    // The next entry meeting box b, -1 after the last.
    int next(int count, const SplatBounds* bounds, const Box& b) {
        if (std::memcmp(&b, &box, sizeof(Box)) != 0) {  // (the first call: nothing pulled yet, nothing to test)
            box = b;
            if (src.band && !(b.ya >= src.lo && b.yb <= src.hi)) {  // as Cursor::next: on from the last returned
                src.band = nullptr;
                src.i = last;
                n = at = 0;
            }
            test(bounds);
        }
        while (!hits) {
            n = at = 0;
            for (int e; n < CHUNK && (e = src.next(count, b.ya, b.yb)) >= 0;) idx[n++] = e;
            if (!n) return -1;
            test(bounds);
        }
        const int p = __builtin_ctz(hits);
        hits &= hits - 1;
        at = p + 1;
        return last = idx[p];
    }

  private:
    void test(const SplatBounds* bounds) {
        uint32_t h = 0;
        for (int p = at; p < n; ++p) {
            // `outside`'s test without its branches (which serve the walks testing entry by entry: scalar's walk
            // is 3-6 % slower with this form there)
            const SplatBounds& e = bounds[idx[p]];
            h |= (uint32_t)!((box.yb < e.y0) | (box.ya > e.y1) | (box.xb < e.x0) | (box.xa > e.x1)) << p;
        }
        hits = h;
    }
};

// A lane group: N pixels of one row, `count` of them inside the tile. [xa, xb] x [ya, yb]: the box a splat's
// SplatBounds must meet to matter to any lane (the lanes' pixel centres; for gaussian_blending the lanes' window
// centres grown by their largest half perimeter, updated as the windows move).
template <class L>
struct Group {
    int x, y;  // the first lane's pixel
    typename L::F px, py;
    typename L::M live;
    float xa, xb, ya, yb;
    int count;
    Cursor entries;
};

// Per-lane outputs of a group before they are written to the image.
template <int N>
struct Out {
    float C[3][N], T[N], S[N], wx[N], wy[N];  // PixelSums per lane (S: wsr, duplex), window sides
    int32_t evals[N];
};

// Walk the list for one group: `step(splat, live) -> stopped lanes`. A lane's evals is the list position where it
// stopped (+1), else n: the same count as one pixel walking the list (skipped entries count as walked).
// Filter: the entries through Filtered (gaussian_blending's vector groups, which skip most of their lists; the alpha
// modes' groups meet most entries of theirs, and there the chunks cost more than they save). A trace tests entry by
// entry.
template <class L, class Tr, bool Filter = false, class Step>
void walk(const TileJob& job, const Group<L>& g, Out<L::N>& out, Step step) {
    typename L::M live = g.live;
    for (int i = 0; i < L::N; ++i) out.evals[i] = job.n;
    Cursor entries = g.entries;
    Filtered hits(g.entries);
    for (int i;;) {
        if constexpr (Filter && std::is_same_v<Tr, NoTrace>) {
            if ((i = hits.next(job.n, job.bounds, Box{g.xa, g.xb, g.ya, g.yb})) < 0) break;
        } else {
            if ((i = entries.next(job.n, g.ya, g.yb)) < 0) break;
            if (outside(job.bounds[i], g.xa, g.xb, g.ya, g.yb)) {
                GBV_TRACE(Tr, entry(i, SKIP_BOX));
                continue;
            }
            GBV_TRACE(Tr, entry(i, SKIP_NONE));
        }
        const typename L::M stop = step(job.list[i], live);
        const uint32_t bits = L::bits(stop);
        if (!bits) continue;
        GBV_TRACE(Tr, stopped(stop));
        for (int k = 0; k < L::N; ++k)
            if ((bits >> k) & 1u) out.evals[k] = i + 1;
        live = L::and_not(live, stop);
        if (!L::any(live)) {
            GBV_TRACE(Tr, unreached(i + 1, job.n));
            break;
        }
    }
}

}  // namespace tile
}  // namespace gbv
