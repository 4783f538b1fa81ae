// GLSL port of native/include/gbv/ray3d.h (a splat at its maximum along a pixel's ray: eval3d, stopthepop's depth),
// function by function with the same names; ray3d.h documents them. Needs common.glsl. finish_ray_splat (which needs
// the preprocess) is ray3d_finish.glsl, sorted_fragment (which needs the blend) resort.glsl.

const float STOPTHEPOP_MIN_SCALE = 1e-3;

// port of ray3d.h: RaySplat
struct RaySplat {
    vec3 c, u0, a0, a1;
    int ortho;
};

// RaySplat in RAY_VEC4S vec4: c + ortho (int bits), u0, a0, a1.
void pack_ray(RaySplat r, out vec4 p0, out vec4 p1, out vec4 p2, out vec4 p3) {
    p0 = vec4(r.c, intBitsToFloat(r.ortho));
    p1 = vec4(r.u0, 0.0);
    p2 = vec4(r.a0, 0.0);
    p3 = vec4(r.a1, 0.0);
}

RaySplat unpack_ray(vec4 p0, vec4 p1, vec4 p2, vec4 p3) {
    return RaySplat(p0.xyz, p1.xyz, p2.xyz, p3.xyz, floatBitsToInt(p0.w));
}

// port of ray3d.h: dot3
float dot3(vec3 a, vec3 b) {
    precise float d = a.x * b.x + a.y * b.y + a.z * b.z;
    return d;
}

// port of ray3d.h: ray_splat (quat is (w, x, y, z))
bool ray_splat(CameraParams cam, vec3 mean, vec4 quat, vec3 scale, float filter_3d, float min_scale, out RaySplat o) {
    precise vec3 pv;
    for (int i = 0; i < 3; ++i)
        pv[i] = cam.R[i * 3] * mean.x + cam.R[i * 3 + 1] * mean.y + cam.R[i * 3 + 2] * mean.z + cam.t[i];
    const float r = quat.x, x = quat.y, y = quat.z, z = quat.w;
    precise float Rq[9];
    Rq[0] = 1.0 - 2.0 * (y * y + z * z);
    Rq[1] = 2.0 * (x * y - r * z);
    Rq[2] = 2.0 * (x * z + r * y);
    Rq[3] = 2.0 * (x * y + r * z);
    Rq[4] = 1.0 - 2.0 * (x * x + z * z);
    Rq[5] = 2.0 * (y * z - r * x);
    Rq[6] = 2.0 * (x * z - r * y);
    Rq[7] = 2.0 * (y * z + r * x);
    Rq[8] = 1.0 - 2.0 * (x * x + y * y);
    const bool ortho = cam.projection == ORTHOGRAPHIC;
    bool ok = true;
    for (int i = 0; i < 3; ++i) {
        float s = scale[i] > min_scale ? scale[i] : min_scale;
        if (filter_3d > 0.0) {
            precise float s2 = s * s + filter_3d * filter_3d;
            s = sqrt(s2);
        }
        ok = ok && s > 0.0;
        precise vec3 row;
        for (int k = 0; k < 3; ++k)
            row[k] = (cam.R[k * 3] * Rq[i] + cam.R[k * 3 + 1] * Rq[3 + i] + cam.R[k * 3 + 2] * Rq[6 + i]) / s;
        o.c[i] = ortho ? pv.z * row.z : dot3(row, pv);
        o.u0[i] = ortho ? row.z : o.c[i] / pv.z;
        o.a0[i] = row.x / cam.fx;
        o.a1[i] = row.y / cam.fy;
        ok = ok && finitef(o.c[i]) && finitef(o.u0[i]) && finitef(o.a0[i]) && finitef(o.a1[i]);
    }
    o.ortho = ortho ? 1 : 0;
    return ok;
}

// port of ray3d.h: ray_max
float ray_max(RaySplat s, float dx, float dy, out float t) {
    precise vec3 w = dx * s.a0 + dy * s.a1;
    const vec3 u = s.ortho != 0 ? s.u0 : s.u0 + w;
    const vec3 r = s.ortho != 0 ? s.c - w : s.c;
    const float uu = dot3(u, u);
    t = dot3(r, u) / uu;
    if (!(t > 0.0)) return dot3(r, r);
    const vec3 c = s.ortho != 0 ? s.u0 : s.c;
    precise vec3 n = vec3(c.y * w.z - c.z * w.y, c.z * w.x - c.x * w.z, c.x * w.y - c.y * w.x);
    return dot3(n, n) / uu;
}

// port of ray3d.h: ray_footprint (box: x0, x1, y0, y1; an array: llvmpipe loses a dvec4's last component). The
// values C++ multiplies through dmul_rn are `precise`.
int ray_footprint(RaySplat s, float log_min_alpha, out double box[4]) {
    box = double[4](0.0, 0.0, 0.0, 0.0);
    const dvec3 c = dvec3(s.c), a0 = dvec3(s.a0), a1 = dvec3(s.a1), u0 = dvec3(s.u0);
    precise double cc = dot(c, c);
    const double r0 = -2.0 * double(log_min_alpha);
    if (!(r0 >= 0.0)) return 0;
    precise double rad = sqrt(r0) * (1.0 + 1e-4) + 1e-6 * sqrt(cc) + 1e-4;
    const double r2 = rad * rad;
    precise double K00, K01, K11, K02 = 0.0, K12 = 0.0, K22 = -r2;
    if (s.ortho != 0) {
        const double nn = dot(u0, u0);
        if (!(nn > 0.0)) return 2;
        const double p0 = dot(a0, u0), p1 = dot(a1, u0);
        K00 = dot(a0, a0) - p0 * p0 / nn;
        K01 = dot(a0, a1) - p0 * p1 / nn;
        K11 = dot(a1, a1) - p1 * p1 / nn;
    } else {
        const double g = cc - r2;
        if (!(g > 0.0)) return 2;
        precise double b0 = dot(a0, c), b1 = dot(a1, c), b2 = dot(u0, c);
        K00 = g * dot(a0, a0) - b0 * b0;
        K01 = g * dot(a0, a1) - b0 * b1;
        K11 = g * dot(a1, a1) - b1 * b1;
        K02 = g * dot(a0, u0) - b0 * b2;
        K12 = g * dot(a1, u0) - b1 * b2;
        K22 = g * dot(u0, u0) - b2 * b2;
    }
    precise double det = K00 * K11 - K01 * K01;
    if (!(K00 > 0.0) || !(det > 0.0)) return 2;
    const double i00 = K11 / det, i01 = -K01 / det, i11 = K00 / det;
    precise double cx = -(i00 * K02 + i01 * K12), cy = -(i01 * K02 + i11 * K12);
    precise double qmin = K22 + K02 * cx + K12 * cy;
    if (!(qmin <= 0.0)) return qmin > 0.0 ? 0 : 2;
    const double hx = sqrt(-qmin * i00), hy = sqrt(-qmin * i11);
    if (!finitef(float(hx)) || !finitef(float(hy)) || !finitef(float(cx)) || !finitef(float(cy))) return 2;
    precise double pad = 0.01 + 1e-6 * (abs(cx) + abs(cy) + hx + hy);
    box = double[4](cx - hx - pad, cx + hx + pad, cy - hy - pad, cy + hy + pad);
    return 1;
}

// port of ray3d.h: footprint_tiles
TileRect footprint_tiles(vec2 xy, int kind, double box[4], int gx, int gy) {
    if (kind == 2) return TileRect(0, 0, gx, gy);
    if (kind == 0) return TileRect(0, 0, 0, 0);
    precise double slack = 1e-6 * (abs(double(xy.x)) + abs(double(xy.y)));
    const double p[4] =
        double[4](double(xy.x) - slack, double(xy.x) + slack, double(xy.y) - slack, double(xy.y) + slack);
    int r[4];  // x0, x1, y0, y1
    for (int k = 0; k < 4; ++k) {
        const double t = floor((p[k] + box[k] - 0.5) / double(TILE)) + double(k % 2);
        r[k] = int(min(max(t, 0.0), double(k < 2 ? gx : gy)));
    }
    return TileRect(r[0], r[2], r[1], r[3]);
}
