// GLSL port of ray3d.h's finish_ray_splat (eval3d's and stopthepop's finish of a splat). Needs preprocess.glsl and
// ray3d.glsl.

// port of ray3d.h: finish_ray_splat
bool finish_ray_splat(SplatIn in_, StageSplat st, CameraParams cam, int mode, int gx, int gy, inout Splat2D s,
                      inout TileRect rect, out RaySplat ray) {
    const bool ok = ray_splat(cam, in_.mean, in_.quat, in_.scale, in_.filter_3d,
                              mode == STOPTHEPOP ? STOPTHEPOP_MIN_SCALE : 0.0, ray);
    if (mode != EVAL3D) return ok;
    s.xy = st.xy;
    s.depth = st.depth;
    s.opacity = st.opacity;
    s.conic = vec3(0.0);
    s.color = st.color;
    s.v1 = vec2(0.0);
    s.sigma1 = s.sigma2 = s.inv_sigma1 = s.inv_sigma2 = s.radius = 0.0;
    s.log_min_alpha = logf(MIN_ALPHA_3DGS / st.opacity);
    s.cell = -1;
    double box[4];
    const int kind = ok && st.opacity >= MIN_ALPHA_3DGS ? ray_footprint(ray, s.log_min_alpha, box) : 0;
    rect = footprint_tiles(s.xy, kind, box, gx, gy);
    return rect.x1 > rect.x0 && rect.y1 > rect.y0;
}
