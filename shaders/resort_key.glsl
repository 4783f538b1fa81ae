// GLSL port of native/include/gbv/resort.h's per-splat rules of StopThePop's hierarchy (the tile key and the 4x4
// culling; the C++ documents them), with the same names. `precise` where the C++ multiplies through mul_rn. Needs
// ray3d.glsl.

// port of resort.h: TILE_KEY_OFFSET
const float TILE_KEY_OFFSET = 8.0;

// port of resort.h: rect_max_power
float rect_max_power(Splat2D s, float x0, float y0, float w, float h, out float mx, out float my) {
    precise const float a = s.conic[0], b = s.conic[1], c = s.conic[2];
    precise const float xmd = x0 - s.xy.x, ymd = y0 - s.xy.y;
    const float left = xmd > 0.0 ? 1.0 : 0.0, above = ymd > 0.0 ? 1.0 : 0.0;
    const float out_x = left + (s.xy.x > x0 + w ? 1.0 : 0.0), out_y = above + (s.xy.y > y0 + h ? 1.0 : 0.0);
    mx = s.xy.x;
    my = s.xy.y;
    if (!(out_x + out_y > 0.0)) return 0.0;
    precise const float px = left > 0.0 ? x0 : x0 + w, py = above > 0.0 ? y0 : y0 + h;
    const float dx = xmd < 0.0 ? -w : w, dy = ymd < 0.0 ? -h : h;
    precise const float diffx = s.xy.x - px, diffy = s.xy.y - py;
    precise const float fx = (dx * a * diffx + dx * b * diffy) / (w * w * a);
    precise const float fy = (dy * b * diffx + dy * c * diffy) / (h * h * c);
    const float tx = fx > 0.0 ? (fx < 1.0 ? fx : 1.0) : 0.0, ty = fy > 0.0 ? (fy < 1.0 ? fy : 1.0) : 0.0;
    precise const float qx = px + out_y * tx * dx, qy = py + out_x * ty * dy;
    mx = qx;
    my = qy;
    precise const float ex = s.xy.x - qx, ey = s.xy.y - qy;
    precise const float r = 0.5 * (a * ex * ex + c * ey * ey) + b * ex * ey;
    return r;
}

// port of resort.h: ray_depth
float ray_depth(Splat2D s, RaySplat r, float qx, float qy) {
    float t;
    ray_max(r, qx - s.xy.x, qy - s.xy.y, t);
    return t;
}

// port of resort.h: tile_depth_key
float tile_depth_key(Splat2D s, RaySplat r, float x0, float y0, float cx, float cy, float fx, float fy) {
    float mx, my;
    rect_max_power(s, x0, y0, float(TILE - 1), float(TILE - 1), mx, my);
    precise float t = ray_depth(s, r, mx, my);
    if (r.ortho == 0) {
        precise const float u = (mx - cx) / fx, v = (my - cy) / fy;
        t = t * sqrt(u * u + v * v + 1.0);
    }
    precise const float key = t + TILE_KEY_OFFSET;
    return key > 0.0 ? key : 0.0;
}

// port of resort.h: subtile_culled
bool subtile_culled(Splat2D s, float x0, float y0) {
    float mx, my;
    const float p = rect_max_power(s, x0, y0, 3.0, 3.0, mx, my);
    return minf(MAX_ALPHA, s.opacity * expf(-p)) < MIN_ALPHA_3DGS;
}
