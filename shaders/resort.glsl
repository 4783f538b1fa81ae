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
bool fragment_before(Fragment a, Fragment b) { return a.depth < b.depth || (a.depth == b.depth && a.entry < b.entry); }

// port of resort.h: blend_fragment
bool blend_fragment(Fragment f, vec3 color, inout float T, inout vec3 C) {
    return composite_scalar(f.alpha, color, T, C);
}

// port of resort.h: queue_drop
void queue_drop(inout Fragment q[MAX_QUEUE], inout int n, int k) {
    for (int j = k; j < n; ++j) q[j - k] = q[j];
    n -= k;
}

// port of resort.h: HIER_TAIL, HIER_MID, HIER_LOAD, HIER_PULL, HIER_GROUP (HIER_TAIL = MAX_QUEUE: the 4x4 queue uses
// the queue functions above)
const int HIER_TAIL = 64;
const int HIER_MID = 8;
const int HIER_LOAD = 32;
const int HIER_PULL = 16;
const int HIER_GROUP = 4;

// port of resort.h: queue_insert for the 2x2 queue's merge
void queue_insert(inout Fragment q[HIER_MID], inout int n, Fragment f) {
    int k = n;
    for (; k > 0 && q[k - 1].depth > f.depth; --k) q[k] = q[k - 1];
    q[k] = f;
    ++n;
}

// port of resort.h: HierState
struct HierState {
    Fragment tail[HIER_TAIL];
    Fragment mid[HIER_MID];
    Fragment q[MAX_QUEUE];
    int tn, mn, qn;
    bool done;
};

// port of resort.h: HierPixel
struct HierPixel {
    float px, py, sx, sy, mx, my;
};

// port of resort.h: hier_pixel_at
HierPixel hier_pixel_at(int tx0, int ty0, int x, int y) {
    const int x4 = tx0 + ((x - tx0) & ~3), y4 = ty0 + ((y - ty0) & ~3);
    const int x2 = tx0 + ((x - tx0) & ~1), y2 = ty0 + ((y - ty0) & ~1);
    return HierPixel(float(x) + 0.5, float(y) + 0.5, float(x4) + 0.5, float(y4) + 0.5, float(x2) + 1.0,
                     float(y2) + 1.0);
}

// The list entry i of the list starting at `first` (blend.comp defines them): the walk's src.splat and src.ray.
Splat2D hier_splat(uint first, int i);
RaySplat hier_ray(uint first, int i);

// port of resort.h: hier_arrive
void hier_arrive(uint first, int entry, int loaded, int K, HierPixel g, inout HierState h, inout float T, inout vec3 C,
                 inout int ev) {
    if (h.done) return;
    if (h.qn == K) {
        h.done = blend_fragment(h.q[0], hier_splat(first, h.q[0].entry).color, T, C);
        queue_pop(h.q, h.qn);
        if (h.done) {
            ev = loaded;
            return;
        }
    }
    Fragment f = Fragment(0.0, 0.0, entry);
    if (sorted_fragment(STOPTHEPOP, hier_splat(first, entry), hier_ray(first, entry), g.px, g.py, f.alpha, f.depth))
        queue_insert(h.q, h.qn, f);
}

// port of resort.h: hier_finish
void hier_finish(uint first, inout HierState h, inout float T, inout vec3 C) {
    for (int k = 0; k < h.qn && !h.done; ++k)
        h.done = blend_fragment(h.q[k], hier_splat(first, h.q[k].entry).color, T, C);
}

// port of resort.h: hier_group (what goes on goes to the pixel: hier_arrive, as hier_walk's emit)
void hier_group(uint first, int from, int count, int loaded, int K, HierPixel g, inout HierState h, inout float T,
                inout vec3 C, inout int ev) {
    if (h.done) return;
    Fragment m[HIER_MID];
    int mn = 0;
    for (int k = 0; k < h.mn; ++k) m[mn++] = h.mid[k];
    for (int k = from; k < from + count; ++k) {
        const int e = h.tail[k].entry;
        queue_insert(m, mn, Fragment(ray_depth(hier_splat(first, e), hier_ray(first, e), g.mx, g.my), 0.0, e));
    }
    const int gone = h.mn < 0 ? 0 : min(mn, HIER_GROUP);
    h.mn = 0;
    for (int k = gone; k < mn; ++k) h.mid[h.mn++] = m[k];
    for (int k = 0; k < gone; ++k) hier_arrive(first, m[k].entry, loaded, K, g, h, T, C, ev);
}

// port of resort.h: hier_release
void hier_release(uint first, int count, int loaded, int K, HierPixel g, inout HierState h, inout float T, inout vec3 C,
                  inout int ev) {
    for (int k = 0; k < count; k += HIER_GROUP)
        hier_group(first, k, min(count - k, HIER_GROUP), loaded, K, g, h, T, C, ev);
    queue_drop(h.tail, h.tn, count);
}

// port of resort.h: hier_load
void hier_load(uint first, int i, HierPixel g, inout HierState h) {
    const Splat2D s = hier_splat(first, i);
    if (subtile_culled(s, g.sx, g.sy)) return;
    queue_insert(h.tail, h.tn, Fragment(ray_depth(s, hier_ray(first, i), g.sx + 1.5, g.sy + 1.5), 0.0, i));
}

// port of resort.h: hier_stream (emitting to the pixel)
void hier_stream(uint first, int n, int K, HierPixel g, inout HierState h, inout float T, inout vec3 C, inout int ev) {
    h.tn = 0;
    h.mn = -1;
    for (int base = 0; base < n && !h.done; base += HIER_LOAD) {
        const int end = min(base + HIER_LOAD, n);
        for (int i = base; i < end; ++i) hier_load(first, i, g, h);
        while (h.tn > HIER_LOAD && !h.done) hier_release(first, HIER_PULL, end, K, g, h, T, C, ev);
    }
    hier_release(first, h.tn, n, K, g, h, T, C, ev);
    for (int k = 0; k < h.mn && !h.done; ++k) hier_arrive(first, h.mid[k].entry, n, K, g, h, T, C, ev);
}

// port of resort.h: hier_walk
int hier_walk(uint first, int n, int K, int tx0, int ty0, int x, int y, inout float T, inout vec3 C) {
    HierState h;
    h.qn = 0;
    h.done = false;
    const HierPixel g = hier_pixel_at(tx0, ty0, x, y);
    int ev = n;
    hier_stream(first, n, K, g, h, T, C, ev);
    hier_finish(first, h, T, C);
    return ev;
}
