// Throughput probe for the benchmark: n exp evaluations through a lane type's exp, as the blend steps call it (the
// caller times it; the sum keeps the work from being optimised away).
#pragma once

#include <cstdint>

namespace gbv {

template <class L>
float exp_sum(int64_t n) {
    float start[L::N];
    for (int k = 0; k < L::N; ++k) start[k] = -0.001f * (float)k;
    typename L::F x = L::load(start), acc = L::set(0.0f);
    const typename L::F step = L::set(-1e-7f);
    for (int64_t i = 0; i < n; i += 4 * L::N) {  // four independent exps per iteration, as a blend step has
        acc = acc + L::exp(x) + L::exp(x + step) + L::exp(x + step + step) + L::exp(x - step);
        x = x + step;
    }
    float out[L::N];
    L::store(acc, out);
    float sum = 0.0f;
    for (int k = 0; k < L::N; ++k) sum += out[k];
    return sum;
}

}  // namespace gbv
