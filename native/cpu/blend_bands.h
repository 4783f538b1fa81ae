// Building a tile list's row bands (Bands, blend_tile.h). When splats are small against the tile (zoomed out, a level
// of detail cut) each row's band is a fraction of the list, and its lane groups stop testing every entry.
#pragma once

#include <algorithm>
#include <cstdint>
#include <vector>

#include "blend_tile.h"

namespace gbv {

// Fills `out` for the n entries' bounds of a tile whose pixel rows are y0 .. y0 + pixel_rows - 1, one band per `step`
// rows (a lane group's rows, TileJob::group_rows); false (and `out` unspecified) when the bands would not save work: a
// short list, or entries reaching most bands of the tile on average.
inline bool build_bands(const SplatBounds* b, int n, int y0, int pixel_rows, int step, float margin, Bands& out) {
    const int rows = (pixel_rows + step - 1) / step;  // bands
    if (n < 64 || rows < 2 || pixel_rows > TILE) return false;
    for (int r = 0; r < rows; ++r) {
        const float yc = (float)(y0 + r * step) + 0.5f;  // as blend_tile's group box: its first and last rows' centres
        out.lo[r] = yc - margin;
        out.hi[r] = yc + (float)(std::min(step, pixel_rows - r * step) - 1) + margin;
    }
    out.first.resize(n);
    out.last.resize(n);
    int64_t cover[TILE + 1] = {};  // entries starting at row r minus those ending before it
    const float rows_f = (float)rows;
    for (int i = 0; i < n; ++i) {
        const float y0 = b[i].y0, y1 = b[i].y1;
        int f = 0, l = rows - 1;  // a NaN bound meets every band (as `outside`, whose tests a NaN fails)
        if (y0 == y0 && y1 == y1) {
            // f: the first band with hi >= y0; l: the last with lo <= y1 (both monotone in r): from a guess within
            // one band (a truncation), then exact against the bands themselves
            f = (int)std::min(std::max((y0 - out.hi[0]) / (float)step, 0.0f), rows_f);
            while (f > 0 && out.hi[f - 1] >= y0) --f;
            while (f < rows && out.hi[f] < y0) ++f;
            l = (int)std::min(std::max((y1 - out.lo[0]) / (float)step, -1.0f), rows_f - 1.0f);
            while (l < rows - 1 && out.lo[l + 1] <= y1) ++l;
            while (l >= 0 && out.lo[l] > y1) --l;
        }
        out.first[i] = (int8_t)f;
        out.last[i] = (int8_t)l;
        if (f <= l) ++cover[f], --cover[l + 1];
    }
    out.start[0] = 0;
    int64_t rows_covered = 0;
    for (int r = 0; r < rows; ++r) {
        rows_covered += cover[r];
        out.start[r + 1] = out.start[r] + rows_covered;
    }
    if (out.start[rows] * 2 > (int64_t)n * rows) return false;
    out.idx.resize(out.start[rows]);
    int64_t at[TILE];
    std::copy(out.start, out.start + rows, at);
    for (int i = 0; i < n; ++i)
        for (int r = out.first[i]; r <= out.last[i]; ++r) out.idx[at[r]++] = i;
    return true;
}

}  // namespace gbv
