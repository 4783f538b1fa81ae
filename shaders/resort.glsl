// GLSL port of native/include/gbv/resort.h (the per-pixel order of eval3d and stopthepop) and ray3d.h's
// sorted_fragment, with the same names; the C++ documents them. Needs blend.glsl and ray3d.glsl.

// port of ray3d.h: sorted_fragment
bool sorted_fragment(int mode, Splat2D s, RaySplat ray, float px, float py, out float alpha, out float depth) {
    alpha = 0.0;
    float t;
    const float E = ray_max(ray, px - s.xy.x, py - s.xy.y, t);
    float power;
    if (mode == STOPTHEPOP) {
        if (!(t >= 0.0)) return false;
        power = gaussian_power(s, s.xy - vec2(px, py));
        depth = t;
    } else {
        power = -0.5 * E;
        depth = t > 0.0 ? t : 0.0;
    }
    if (!(power <= 0.0) || power < s.log_min_alpha) return false;
    alpha = minf(s.opacity * expf(power), MAX_ALPHA);
    return alpha >= MIN_ALPHA_3DGS;
}

// port of resort.h: Fragment
struct Fragment {
    float depth, alpha;
    int entry;
};

// port of resort.h: queue_insert
void queue_insert(inout Fragment q[MAX_QUEUE], inout int n, Fragment f) {
    int k = n;
    for (; k > 0 && q[k - 1].depth > f.depth; --k) q[k] = q[k - 1];
    q[k] = f;
    ++n;
}

// port of resort.h: queue_pop
void queue_pop(inout Fragment q[MAX_QUEUE], inout int n) {
    for (int k = 1; k < n; ++k) q[k - 1] = q[k];
    --n;
}

// port of resort.h: fragment_before
bool fragment_before(Fragment a, Fragment b) {
    return a.depth < b.depth || (a.depth == b.depth && a.entry < b.entry);
}

// port of resort.h: blend_fragment
bool blend_fragment(Fragment f, vec3 color, inout float T, inout vec3 C) {
    return composite_scalar(f.alpha, color, T, C);
}
