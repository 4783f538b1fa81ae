// Test switches of the CPU driver (gbviewer._native.testing): process-wide, off the render path unless a test sets
// them.
#pragma once

#include <atomic>
#include <cstdint>
#include <mutex>
#include <utility>
#include <vector>

#include "gbv/common.h"

namespace gbv::cpu::testing {

// Skip lane groups outside a splat's pixel box (the default) or evaluate every list entry (to show the boxes change
// no pixel).
extern std::atomic<bool> pixel_boxes;

// A lane group walks its row's band of the tile list (blend_bands.h) where the bands save work (the default), or the
// whole list (to show the bands change no pixel); gaussian_blending's bands reach this far (px) about the row's pixel
// centres (its group box starts 1.001 px about them: just above that, windows leave the band at once).
extern std::atomic<bool> row_bands;
extern std::atomic<float> gaussian_band_margin;

// The level-of-detail cut walks the tree top down; it evaluates every node instead (lod_cut.cpp) once a level's
// reached nodes are more than this many, a quarter of the level, and most of them open on; 0 forces the full
// evaluation for any tree, to show both give the same cut.
extern std::atomic<int64_t> cut_flat_above;

// gbviewer._native.lod.cut stops (as if cancelled) once it has asked its stop this many times; -1: never (default).
extern std::atomic<int64_t> cut_stop_after;

// Fill each new image with NaN (evaluation counts -1) before the blend, to show that it writes every pixel.
extern std::atomic<bool> poison_images;

// Keep a copy of the last frame's preprocess output (per splat: the valid flag, then the Splat2D and TileRect bytes
// when valid, zeros when culled), so tests can compare the SIMD paths' preprocess bit for bit.
extern std::atomic<bool> capture;
void record_preprocess(const Splat2D* splats, const TileRect* rects, const uint8_t* valid, int64_t n);
std::vector<uint8_t> captured_preprocess();
// ... and of its tile lists (bin_frame's tile_start and ids), each entry as its depth key (depth bits << 32 | splat
// id; only the id where not depth_keys: duplex).
void record_lists(const std::vector<int64_t>& tile_start, const std::vector<uint32_t>& ids,
                  const std::vector<Splat2D>& splats, bool depth_keys);
std::pair<std::vector<int64_t>, std::vector<uint64_t>> captured_lists();

// How many of the floats with bit patterns in [begin, end) (multiples of 4) half_bits (half.h) converts otherwise
// than the F16C instruction; -1 where the CPU has no F16C (or is not x86-64).
int64_t half_mismatches(uint64_t begin, uint64_t end);

}  // namespace gbv::cpu::testing
