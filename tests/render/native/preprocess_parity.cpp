// tests/render/test_fp_contract.py builds this twice around native/include/gbv (contraction off, and forced on with FMA
// instructions) and compares the outputs byte for byte. It reads a scene and a camera from argv[1], runs make_camera,
// then preprocess_splat in every mode (and preprocess_cell on the same ellipsoids) and writes argv[2]: the
// CameraParams, then per mode and splat one Record.
//
// Input (little-endian): int32 n, k (SH coefficients per channel), weight_k; float R[9], t[3], fx, fy, cx, cy;
// int32 width, height; float near, sigma; int32 projection; then float arrays means (n,3), scales (n,3), quats (n,4),
// opacities (n), filter_3d (n), sh (n,k,3), weight_sh (n,weight_k).
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <vector>

#include "gbv/camera.h"
#include "gbv/preprocess.h"

using namespace gbv;

namespace {

// The decision, the tile rectangle and the fields splat_less (native/include/gbv/order.h) orders a cell's splats by.
struct Record {
    int32_t valid;
    TileRect rect;
    float depth, x, y, opacity, conic[3], color[3], radius, log_min_alpha;
    int32_t cell;
};

template <typename T>
bool read(FILE* f, T* dst, size_t count) {
    return std::fread(dst, sizeof(T), count, f) == count;
}

}  // namespace

int main(int argc, char** argv) {
    if (argc != 3) {
        std::fprintf(stderr, "usage: %s INPUT OUTPUT\n", argv[0]);
        return 2;
    }
    FILE* in = std::fopen(argv[1], "rb");
    if (!in) return 2;
    int32_t hdr[3];
    float camf[16];
    int32_t size[2];
    float nears[2];
    int32_t projection;
    if (!read(in, hdr, 3) || !read(in, camf, 16) || !read(in, size, 2) || !read(in, nears, 2) ||
        !read(in, &projection, 1))
        return 3;
    const int64_t n = hdr[0];
    const int k = hdr[1], wk = hdr[2];
    std::vector<float> means(n * 3), scales(n * 3), quats(n * 4), opac(n), filt(n), sh(n * k * 3), w(n * wk);
    if (!read(in, means.data(), means.size()) || !read(in, scales.data(), scales.size()) ||
        !read(in, quats.data(), quats.size()) || !read(in, opac.data(), opac.size()) ||
        !read(in, filt.data(), filt.size()) || !read(in, sh.data(), sh.size()) || !read(in, w.data(), w.size()))
        return 3;
    std::fclose(in);

    const CameraParams cam = make_camera(camf, camf + 9, camf[12], camf[13], camf[14], camf[15], size[0], size[1],
                                         nears[0], (Projection)projection);
    const int gx = (cam.width + TILE - 1) / TILE, gy = (cam.height + TILE - 1) / TILE;
    struct Run {
        Mode mode;
        bool weights;
        int depth_correct;
    };
    const Run runs[] = {{SCALAR, false, 0}, {MIP, false, 0}, {ANALYTIC, false, 0}, {GAUSSIAN_BLENDING, false, 0},
                        {WSR, true, 0},     {WSR, true, 1},  {DUPLEX, true, 1}};
    std::vector<Record> out;
    out.reserve((sizeof(runs) / sizeof(runs[0]) + 1) * n);
    for (const Run& run : runs) {
        const OitParams oit{nears[1], 1.0f, 4.0f, run.depth_correct};
        for (int64_t i = 0; i < n; ++i) {
            SplatIn s{&means[3 * i],
                      &scales[3 * i],
                      &quats[4 * i],
                      opac[i],
                      &sh[(size_t)k * 3 * i],
                      filt[i],
                      run.weights && wk ? &w[(size_t)wk * i] : nullptr,
                      sh_degree_for_coeffs(wk),
                      run.mode == DUPLEX ? (int32_t)(i % 7) : -1};
            Splat2D p;
            std::memset(&p, 0, sizeof(p));
            Record r;
            std::memset(&r, 0, sizeof(r));
            r.valid = preprocess_splat(s, sh_degree_for_coeffs(k), cam, run.mode, oit, gx, gy, &p, &r.rect);
            if (!r.valid)
                r.rect = TileRect{0, 0, 0, 0};  // unspecified when culled
            else {
                r.depth = p.depth;
                r.x = p.xy.x;
                r.y = p.xy.y;
                r.opacity = p.opacity;
                for (int c = 0; c < 3; ++c) {
                    r.conic[c] = p.conic[c];
                    r.color[c] = p.color[c];
                }
                r.radius = p.radius;
                r.log_min_alpha = p.log_min_alpha;
                r.cell = p.cell;
            }
            out.push_back(r);
        }
    }
    for (int64_t i = 0; i < n; ++i) {  // the same ellipsoids as Duplex cells
        CellIn c{&means[3 * i], &scales[3 * i], &quats[4 * i]};
        Cell2D p{};
        Record r;
        std::memset(&r, 0, sizeof(r));
        r.valid = preprocess_cell(c, cam, gx, gy, &p, &r.rect);
        if (!r.valid)
            r.rect = TileRect{0, 0, 0, 0};
        else {
            r.depth = p.depth;
            r.x = p.xy.x;
            r.y = p.xy.y;
            r.radius = p.radius;
        }
        out.push_back(r);
    }
    FILE* o = std::fopen(argv[2], "wb");
    if (!o) return 2;
    const bool ok = std::fwrite(&cam, sizeof(cam), 1, o) == 1 &&
                    std::fwrite(out.data(), sizeof(Record), out.size(), o) == out.size();
    return std::fclose(o) == 0 && ok ? 0 : 4;
}
