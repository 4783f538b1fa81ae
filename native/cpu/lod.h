// Level of detail (docs/lod.md): an 8-ary splat hierarchy over the Morton order of the splat centres, interior nodes
// moment-matched Gaussians of their leaves, and the per-camera cut through it (lod.cpp; bound in lod_bind.cpp).
#pragma once

#include <cstdint>
#include <functional>
#include <vector>

#include "plane.h"

namespace gbv::lod {

constexpr int BRANCHING = 8;  // children per interior node (the last node of a level may have fewer)

// How an interior node's opacity follows from its leaves (leaf weight a A, A = the mean of the three principal
// cross-section areas): DEPTH keeps the area-weighted optical depth, -ln(1 - alpha_p) A_p = sum -ln(1 - a) A; SUM
// keeps the covered area, alpha_p A_p = sum a A (clamped to 1). OPACITY_WEIGHTS is DEPTH with the children's
// mean, covariance, SH and filter weighted by opacity a alone instead of a A (the alternative the rule is measured
// against: bench/lod_targets.py).
enum OpacityRule { DEPTH = 0, SUM = 1, OPACITY_WEIGHTS = 2 };

// The scene's splats (activated, as gbviewer.Scene; sh float32 (N,K,3); filter_3d may be null).
struct Splats {
    const float *means, *scales, *quats, *opacities, *sh, *filter;
    int64_t n;
    int k;  // SH coefficients per channel
};

// Nodes are numbered flat: 0..N-1 the leaves in Morton order (leaf p is splat order[p]), then the interior nodes
// level by level up to the root; levels[l]..levels[l+1] are level l's ids (level 0 the leaves). Node q of level
// l > 0 has the children levels[l-1] + 8 (q - levels[l]) ... up to the level's end. The interior arrays below are
// indexed by id - N (M = interior nodes).
struct Tree {
    Plane<int32_t> order;  // (N,)
    std::vector<int64_t> levels;  // (L+1,)
    Plane<float> means, scales;  // (M,3): the merged Gaussian; scales the square roots of its eigenvalues
    Plane<float> quats;  // (M,4) w,x,y,z: its eigenvectors
    Plane<float> opacities;  // (M,)
    Plane<float> sh;  // (M,K,3): the leaf-weighted mean of the leaves' SH
    Plane<float> filter;  // (M,) the weighted mean of the leaves' 3D filters (empty without one)
    Plane<float> radius;  // (M,) a sphere about the mean holding every leaf's centre
    Plane<float> size;  // (M,) world footprint of the merged Gaussian: 2 sqrt(largest eigenvalue)
};

Tree build(const Splats& s, OpacityRule rule, int threads);

// The camera as the cut sees it: the eye (perspective) or the forward axis (orthographic), the larger focal length.
struct View {
    double eye[3];
    double focal;
    bool orthographic;
};

// The cut's drawn nodes with their opacity multipliers, as rows: its `leaves` leaves first, as splat indices, in the
// tree's (Morton) order, or ascending when they are over half the splats (where the renderer's stage reads runs of
// consecutive rows), then interior nodes, node_base + interior index (ascending). Along every leaf's path to the
// root the drawn weights sum to 1.
struct Cut {
    Plane<int32_t> rows;
    Plane<float> weights;
    int64_t leaves = 0;
    bool stopped = false;  // the stop said true: rows and weights unspecified
};

// A node of projected size p px is drawn alone when p <= tau, replaced by its children when p >= tau (1 + band),
// and drawn with weight 1 - o beside its children (weight o) in between, o = (p - tau) / (tau band). tau <= 0: the
// leaves. Interior node i: centre means[i], radius, size as in Tree; its row in the Cut is node_base + i (the
// renderer's rows continue the scene's). `stop` (thread-safe; may be empty) is asked every few thousand nodes: once
// it says true the cut returns early, `stopped`, its contents unspecified.
using Stop = std::function<bool()>;
Cut cut(const float* means, const float* radius, const float* size, const int64_t* levels, int num_levels,
        const int32_t* order, const View& v, double tau, double band, int32_t node_base, int threads,
        const Stop& stop = {});

}  // namespace gbv::lod
