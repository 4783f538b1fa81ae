// GLSL port of native/include/gbv/camera.h: the kernels' CameraParams from the Python-side camera values. `precise`
// where the C++ code multiplies through mul_rn: no multiply-add contraction (see common.h).

// port of camera.h: make_camera (the camera's values as arrays and scalars)
CameraParams make_camera(float R[9], float t[3], float fx, float fy, float cx, float cy, int width, int height,
                         float near_plane, int projection) {
    precise CameraParams c;
    for (int i = 0; i < 9; ++i) c.R[i] = R[i];
    for (int i = 0; i < 3; ++i) c.t[i] = t[i];
    for (int i = 0; i < 3; ++i)  // campos = -R^T t
        c.campos[i] = -(R[i] * t[0] + R[3 + i] * t[1] + R[6 + i] * t[2]);
    c.fx = fx;
    c.fy = fy;
    c.cx = cx;
    c.cy = cy;
    c.width = width;
    c.height = height;
    c.near_plane = near_plane;
    c.projection = projection;
    precise const float tan_x = 0.5 * float(width) / fx, tan_y = 0.5 * float(height) / fy;
    c.lim_x_pos = (float(width) - cx) / fx + 0.3 * tan_x;
    c.lim_x_neg = cx / fx + 0.3 * tan_x;
    c.lim_y_pos = (float(height) - cy) / fy + 0.3 * tan_y;
    c.lim_y_neg = cy / fy + 0.3 * tan_y;
    return c;
}
