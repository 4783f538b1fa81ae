// Building the kernels' CameraParams from Python-side camera values (shared by CPU and CUDA drivers).
#pragma once

#include "common.h"

namespace gbv {

// R is row-major world-to-camera; the frustum limits follow gsplat's persp_proj, which equals the
// published 1.3 * tan(fov/2) clamp for a centred principal point (docs/modes.md#covariance-and-projection); an
// orthographic camera has no use for them. `projection`: PERSPECTIVE or ORTHOGRAPHIC (fx, fy then in pixels per world
// unit).
inline CameraParams make_camera(const float R[9], const float t[3], float fx, float fy, float cx, float cy, int width,
                                int height, float near_plane, Projection projection) {
    CameraParams c;
    for (int i = 0; i < 9; ++i) c.R[i] = R[i];
    for (int i = 0; i < 3; ++i) c.t[i] = t[i];
    for (int i = 0; i < 3; ++i)  // campos = -R^T t (products never fused: see mul_rn)
        c.campos[i] = -(mul_rn(R[i], t[0]) + mul_rn(R[3 + i], t[1]) + mul_rn(R[6 + i], t[2]));
    c.fx = fx;
    c.fy = fy;
    c.cx = cx;
    c.cy = cy;
    c.width = width;
    c.height = height;
    c.near_plane = near_plane;
    c.projection = projection;
    const float tan_x = 0.5f * width / fx, tan_y = 0.5f * height / fy;
    c.lim_x_pos = (width - cx) / fx + mul_rn(0.3f, tan_x);
    c.lim_x_neg = cx / fx + mul_rn(0.3f, tan_x);
    c.lim_y_pos = (height - cy) / fy + mul_rn(0.3f, tan_y);
    c.lim_y_neg = cy / fy + mul_rn(0.3f, tan_y);
    return c;
}

}  // namespace gbv
