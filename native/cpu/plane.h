// Plane<T>: a std::vector whose resize leaves new elements uninitialised (image planes, the LOD build's arrays).
#pragma once

#include <memory>
#include <utility>
#include <vector>

namespace gbv {

// An allocator whose new elements are left uninitialised, for buffers that parallel loops write whole: the blend
// writes every pixel of every tile, so an image plane needs no zero fill (a 6400x4800 supersampled frame's was
// 600 MB of serial memset before any cancel check); its pages are first touched by the parallel blend instead.
template <class T>
struct Uninit : std::allocator<T> {
    template <class U>
    struct rebind {
        using other = Uninit<U>;
    };
    Uninit() = default;
    template <class U>
    Uninit(const Uninit<U>&) noexcept {}
    template <class U>
    void construct(U* p) noexcept {
        ::new ((void*)p) U;
    }
    template <class U, class... A>
    void construct(U* p, A&&... a) {
        ::new ((void*)p) U(std::forward<A>(a)...);
    }
};

template <class T>
using Plane = std::vector<T, Uninit<T>>;

}  // namespace gbv
