// The scalar mode's 2D filter as the viewer presets set it (OitParams' filter fields; gbviewer/render/presets.py):
// Sigma' = Sigma + pre_dilation I, never compensated (Spark's preBlurAmount); Sigma'' = Sigma' + dilation I, with
// `compensate` the opacity times sqrt(max(0, det Sigma' / det Sigma'')) (gsplat's add_blur, Spark's blurAmount); a
// splat whose larger eigenvalue of Sigma'' is below cull_lambda px^2 is culled (SuperSplat's 2-pixel early-out).
// The defaults (no pre-dilation, +0.3, no compensation, no cull) compute 3DGS's dilation as before, bit for bit.
// support_power: the lowest Gaussian power -d^2/2 a splat keeps when the preset cuts it at the Mahalanobis radius
// `support` (a viewer whose quad and fragment discard end there), -inf without such a cut.
#pragma once

#include "common.h"
#include "lanes.h"

namespace gbv {

template <class L>
GBV_HD void scalar_filter(const OitParams& f, typename L::F cov[3], typename L::F& opacity, typename L::M& ok) {
    using F = typename L::F;
    if (f.pre_dilation != 0.0f) {
        cov[0] = cov[0] + L::set(f.pre_dilation);
        cov[2] = cov[2] + L::set(f.pre_dilation);
    }
    F det0 = L::set(0.0f);
    if (f.compensate) det0 = L::mul_rn(cov[0], cov[2]) - L::mul_rn(cov[1], cov[1]);
    cov[0] = cov[0] + L::set(f.dilation);
    cov[2] = cov[2] + L::set(f.dilation);
    if (f.compensate) {
        const F det1 = L::mul_rn(cov[0], cov[2]) - L::mul_rn(cov[1], cov[1]);
        opacity = opacity * L::sqrt(L::fmax(L::set(0.0f), det0 / det1));
    }
    if (f.cull_lambda > 0.0f) {
        const F half = L::set(0.5f) * (cov[0] - cov[2]);
        const F root = L::sqrt(L::mul_rn(half, half) + L::mul_rn(cov[1], cov[1]));
        ok = L::and_(ok, L::mul_rn(L::set(0.5f), cov[0] + cov[2]) + root >= L::set(f.cull_lambda));
    }
}

GBV_HD float support_power(const OitParams& f) {
    return f.support > 0.0f ? -0.5f * mul_rn(f.support, f.support) : -INFINITY;
}

}  // namespace gbv
