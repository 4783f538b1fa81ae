// Spherical harmonics of the preprocess (preprocess.h): the real SH basis up to degree 3, the view-dependent colour
// and Sort-free GS's view-dependent weight. Templates over a lane type L (lanes.h), as preprocess.h's steps.
#pragma once

#include "common.h"
#include "lanes.h"

namespace gbv {

constexpr float SH_C0 = 0.28209479177387814f;
constexpr float SH_C1 = 0.4886025119029199f;
// Scalars rather than arrays: nvcc cannot read namespace-scope constexpr arrays in device code.
constexpr float SH_C2_0 = 1.0925484305920792f, SH_C2_1 = -1.0925484305920792f, SH_C2_2 = 0.31539156525252005f,
                SH_C2_3 = -1.0925484305920792f, SH_C2_4 = 0.5462742152960396f;
constexpr float SH_C3_0 = -0.5900435899266435f, SH_C3_1 = 2.890611442640554f, SH_C3_2 = -0.4570457994644658f,
                SH_C3_3 = 0.3731763325901154f, SH_C3_4 = -0.4570457994644658f, SH_C3_5 = 1.445305721320277f,
                SH_C3_6 = -0.5900435899266435f;

// Real SH basis of degree `deg` (0..3) at the unit direction `dir`, in the 3DGS order and signs; returns the
// number of coefficients used, (deg + 1)^2.
template <class L>
GBV_HD int sh_basis(int deg, const typename L::F dir[3], typename L::F basis[16]) {
    using F = typename L::F;
    const F x = dir[0], y = dir[1], z = dir[2];
    basis[0] = L::set(SH_C0);
    if (deg < 1) return 1;
    basis[1] = L::set(-SH_C1) * y;
    basis[2] = L::set(SH_C1) * z;
    basis[3] = L::set(-SH_C1) * x;
    if (deg < 2) return 4;
    const F xx = L::mul_rn(x, x), yy = L::mul_rn(y, y), zz = L::mul_rn(z, z), xy = x * y, yz = y * z, xz = x * z;
    const F two = L::set(2.0f), three = L::set(3.0f), four = L::set(4.0f);
    basis[4] = L::set(SH_C2_0) * xy;
    basis[5] = L::set(SH_C2_1) * yz;
    basis[6] = L::set(SH_C2_2) * (L::mul_rn(two, zz) - xx - yy);
    basis[7] = L::set(SH_C2_3) * xz;
    basis[8] = L::set(SH_C2_4) * (xx - yy);
    if (deg < 3) return 9;
    basis[9] = L::set(SH_C3_0) * y * (L::mul_rn(three, xx) - yy);
    basis[10] = L::set(SH_C3_1) * xy * z;
    basis[11] = L::set(SH_C3_2) * y * (L::mul_rn(four, zz) - xx - yy);
    basis[12] = L::set(SH_C3_3) * z * (L::mul_rn(two, zz) - L::mul_rn(three, xx) - L::mul_rn(three, yy));
    basis[13] = L::set(SH_C3_4) * x * (L::mul_rn(four, zz) - xx - yy);
    basis[14] = L::set(SH_C3_5) * z * (xx - yy);
    basis[15] = L::set(SH_C3_6) * x * (xx - L::mul_rn(three, yy));
    return 16;
}

// View-dependent colour from SH coefficients sh[K][3] (DC first), as computeColorFromSH:
// +0.5 offset, clamped at 0 from below only. With dc_clamp the base colour 0.5 + C0 dc is first clamped to [0, 1], as
// a viewer that stores it in 8 bits does before adding the higher bands (stage_rules).
template <class L>
GBV_HD void sh_to_rgb(const typename L::F* sh, int deg, const typename L::F dir[3], bool dc_clamp,
                      typename L::F out[3]) {
    typename L::F basis[16];
    const int k = sh_basis<L>(deg, dir, basis);
    for (int c = 0; c < 3; ++c) {
        typename L::F v = L::set(0.5f) + L::mul_rn(basis[0], sh[c]);
        if (dc_clamp) v = L::fmin(L::fmax(v, L::set(0.0f)), L::set(1.0f));
        for (int i = 1; i < k; ++i) v = v + L::mul_rn(basis[i], sh[i * 3 + c]);
        out[c] = L::fmax(v, L::set(0.0f));
    }
}

// Sort-free GS's view-dependent weight v_i (docs/modes.md#wsr): a 1-channel SH w[K] (f_do_0, f_ro_*), the raw
// sum: no +0.5, no clamp (non-positive weights are culled by the caller).
template <class L>
GBV_HD typename L::F sh_to_weight(const typename L::F* w, int deg, const typename L::F dir[3]) {
    typename L::F basis[16];
    const int k = sh_basis<L>(deg, dir, basis);
    typename L::F v = L::set(0.0f);
    for (int i = 0; i < k; ++i) v = v + L::mul_rn(basis[i], w[i]);
    return v;
}

}  // namespace gbv
