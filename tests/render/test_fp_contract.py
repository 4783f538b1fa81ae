"""Preprocess decisions are bit-identical whatever the compiler fuses.

Compilers contract a * b + c into one fused multiply-add where they choose: g++ does by default
(-ffp-contract=fast) when the target has FMA instructions, nvcc does by default, GLSL drivers do. A fused sum differs
from the rounded one in the last bit, and for nearly flat splats that decides det > 0, opacity >= min_alpha, w > 0,
the near plane, the depth-correction cut and integer tile edges, so the CPU and CUDA backends counted different
`visible` and `sort_length`. native/include/gbv routes every product that is added or subtracted through mul_rn
(common.h), which no compiler can fuse.

This builds tests/render/native/preprocess_parity.cpp (make_camera, preprocess_splat in every mode, preprocess_cell)
with g++ twice, -O2 -ffp-contract=off and -O2 -ffp-contract=fast with FMA instructions (-mfma on x86-64), runs both on
~100k awkward splats (needles and discs seen edge-on, opacities and view weights at their cuts, depths at the near plane
and at sigma, screen positions on tile edges) and requires identical bytes: every decision, tile rectangle and the
fields the CPU's canonical duplex order (splat_less) compares. A third build with the guard disabled
(GBV_UNGUARDED_PRODUCTS) and contraction on must differ, or these inputs no longer exercise contraction."""

from __future__ import annotations

import os
import platform
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers import skip_or_fail

from gbviewer.model.camera import NEAR_PLANE
from gbviewer.model.scene import SH_C0

REPO = Path(__file__).resolve().parents[2]
SOURCE = Path(__file__).resolve().parent / "native" / "preprocess_parity.cpp"
RUNS = ["scalar", "mip", "analytic", "gaussian_blending", "wsr", "wsr+depth_correct", "duplex+depth_correct", "cell"]
RECORD = np.dtype([("valid", "<i4"), ("rect", "<i4", 4), ("fields", "<u4", 12), ("cell", "<i4")])
CAMERA_BYTES = 4 * (9 + 3 + 3 + 4 + 2 + 1 + 4 + 1)  # CameraParams

# camera and globals of the generated scene; the orthographic camera has the perspective one's scale at depth ORTHO_Z
W, H, FX, FY, CX, CY, SIGMA = 640, 480, 523.7, 517.3, 333.1, 229.9, 7.3
ORTHO_Z = 5.0
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)


def _contract_flags() -> list[str]:
    """Flags that make g++ fuse multiply-adds on this machine (skip_or_fail where it has no FMA instructions)."""
    machine = platform.machine().lower()
    if machine in ("x86_64", "amd64"):
        try:
            flags = Path("/proc/cpuinfo").read_text().split()
        except OSError:
            flags = []
        if "fma" not in flags:
            skip_or_fail("this x86-64 CPU has no FMA instructions, so nothing can be contracted")
        return ["-mfma", "-ffp-contract=fast"]
    if machine in ("aarch64", "arm64"):
        return ["-ffp-contract=fast"]
    skip_or_fail(f"no known FMA flags for {machine}")


@pytest.fixture(scope="module")
def builds(tmp_path_factory) -> dict[str, Path]:
    """The driver built three ways (in parallel): reference (contraction off), contracted, contracted unguarded."""
    cxx = shutil.which(os.environ.get("CXX", "g++")) or shutil.which("g++")
    if cxx is None:
        skip_or_fail("no C++ compiler (g++) on PATH")
    contract = _contract_flags()
    out = tmp_path_factory.mktemp("fp_contract")
    variants = {
        "off": ["-ffp-contract=off"],
        "contracted": contract,
        "unguarded": contract + ["-DGBV_UNGUARDED_PRODUCTS"],
    }
    procs = {}
    for name, flags in variants.items():
        cmd = [
            cxx,
            "-std=c++17",
            "-O2",
            *flags,
            "-I",
            str(REPO / "native" / "include"),
            str(SOURCE),
            "-o",
            str(out / name),
        ]
        procs[name] = (cmd, subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True))
    for cmd, p in procs.values():
        log = p.communicate()[0]
        assert p.returncode == 0, f"{' '.join(cmd)} failed:\n{log}"
    return {name: out / name for name in variants}


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _sh_basis(d: np.ndarray) -> np.ndarray:
    """preprocess.h's sh_basis (degree 3) in float64 for unit directions d (n, 3)."""
    x, y, z = d.T
    xx, yy, zz = x * x, y * y, z * z
    return np.stack(
        [
            np.full_like(x, SH_C0),
            -SH_C1 * y,
            SH_C1 * z,
            -SH_C1 * x,
            SH_C2[0] * x * y,
            SH_C2[1] * y * z,
            SH_C2[2] * (2 * zz - xx - yy),
            SH_C2[3] * x * z,
            SH_C2[4] * (xx - yy),
            SH_C3[0] * y * (3 * xx - yy),
            SH_C3[1] * x * y * z,
            SH_C3[2] * y * (4 * zz - xx - yy),
            SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
            SH_C3[4] * x * (4 * zz - xx - yy),
            SH_C3[5] * z * (xx - yy),
            SH_C3[6] * x * (xx - 3 * yy),
        ],
        1,
    )


def scene_file(path: Path, projection: int = 0, per_kind: int = 12_500, seed: int = 18) -> Path:
    """Eight kinds of splats, per_kind each, written in preprocess_parity.cpp's input format, for a perspective
    (projection 0) or orthographic (1) camera."""
    ortho = projection == 1
    fx, fy = (FX / ORTHO_Z, FY / ORTHO_Z) if ortho else (FX, FY)
    rng = np.random.default_rng(seed)
    R = _rotation(rng)
    t = rng.normal(0, 2, 3)
    kinds = 8
    n = per_kind * kinds
    kind = np.repeat(np.arange(kinds), per_kind)
    u = lambda lo, hi: rng.uniform(lo, hi, n)  # noqa: E731

    # view-space positions inside the frustum, z in 0.5..30
    z = np.exp(u(np.log(0.5), np.log(30.0)))
    px, py = u(0, W), u(0, H)
    scale = np.exp(u(-6.0, 0.0))[:, None] * np.ones((1, 3))
    eps = 10.0 ** u(-7.0, -2.0)
    scale[kind == 0, 1:] *= eps[kind == 0, None]  # 0: needles (rank-1 2D covariance: det is rounding noise)
    scale[kind == 1, 2] *= eps[kind == 1]  # 1: discs, some edge-on
    z[kind == 2] = NEAR_PLANE * (1 + u(-3e-7, 3e-7))[kind == 2]  # 2: at the near plane
    z[kind == 3] = SIGMA * (1 + u(-3e-7, 3e-7))[kind == 3]  # 3: at the depth-correction cut
    # 4: on tile edges: isotropic, 1 px sigma on screen (scalar radius 4), x0 or x1 edge on a multiple of 16 px
    e = kind == 4
    depth = np.ones(n) if ortho else z
    scale[e] = (depth[e] / fx)[:, None]
    r = 4.0
    k = rng.integers(1, W // 16 - 1, n)
    px[e] = np.where(rng.random(n) < 0.5, 16 * k + r + 0.5, 16 * k - r - 15 + 0.5)[e]
    pv = np.stack([(px - CX) * depth / fx, (py - CY) * depth / fy, z], 1)
    means = (pv - t) @ R  # R^T (pv - t), rows
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    opac = u(0.004, 1.0)
    filt = np.zeros(n)
    # 5: Mip-Splatting 3D filter with the compensated opacity at the 1/255 cut
    f = kind == 5
    filt[f] = scale[f, 0] * u(0.3, 3.0)[f]
    s2 = scale[f] ** 2
    ratio = np.prod(s2 / (s2 + filt[f, None] ** 2), 1)
    opac[f] = (1 / 255) / np.sqrt(ratio) * (1 + u(-1e-6, 1e-6)[f])
    # 6: opacities at the 1/255 and 1/256 cuts
    o = kind == 6
    opac[o] = np.where(rng.random(n) < 0.5, 1 / 255, 1 / 256)[o] * (1 + u(-1e-7, 1e-7)[o])
    sh = rng.normal(0, 0.5, (n, 16, 3))
    # view weights: random, and for kind 7 summing to ~0 in the view direction (w > 0 is the cut)
    weight = rng.normal(0, 0.5, (n, 16))
    weight[:, 0] = u(0.5, 3.0)
    d = np.tile(R[2], (n, 1)) if ortho else means - (-R.T @ t)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    basis = _sh_basis(d)
    v = kind == 7
    weight[v, 0] = -(basis[v, 1:] * weight[v, 1:]).sum(1) / SH_C0 * (1 + u(-1e-7, 1e-7)[v])

    with open(path, "wb") as fh:
        fh.write(np.array([n, 16, 16], "<i4").tobytes())
        fh.write(np.concatenate([R.ravel(), t, [fx, fy, CX, CY]]).astype("<f4").tobytes())
        fh.write(np.array([W, H], "<i4").tobytes())
        fh.write(np.array([NEAR_PLANE, SIGMA], "<f4").tobytes())
        fh.write(np.array([projection], "<i4").tobytes())
        for a in (means, scale, quats, opac, filt, sh, weight):
            fh.write(np.ascontiguousarray(a, "<f4").tobytes())
    return path


def run(binary: Path, inp: Path, tmp: Path) -> tuple[bytes, np.ndarray]:
    out = tmp / f"{binary.name}.out"
    p = subprocess.run([str(binary), str(inp), str(out)], capture_output=True, text=True)
    assert p.returncode == 0, f"{binary.name} exited {p.returncode}: {p.stderr}"
    data = out.read_bytes()
    return data[:CAMERA_BYTES], np.frombuffer(data[CAMERA_BYTES:], RECORD).reshape(len(RUNS), -1)


def differences(a: np.ndarray, b: np.ndarray) -> dict[str, tuple[int, int, int]]:
    """Per run: splats whose decision differs, whose tile rectangle differs, whose fields differ (bits)."""
    out = {}
    for i, name in enumerate(RUNS):
        x, y = a[i], b[i]
        dec = x["valid"] != y["valid"]
        both = (x["valid"] == 1) & (y["valid"] == 1)
        rect = both & (x["rect"] != y["rect"]).any(1)
        fields = both & ((x["fields"] != y["fields"]).any(1) | (x["cell"] != y["cell"]))
        out[name] = (int(dec.sum()), int(rect.sum()), int(fields.sum()))
    return out


@pytest.fixture(scope="module", params=[0, 1], ids=["perspective", "orthographic"])
def outputs(request, builds, tmp_path_factory) -> dict[str, tuple[bytes, np.ndarray]]:
    tmp = tmp_path_factory.mktemp("fp_contract_run")
    inp = scene_file(tmp / "scene.bin", request.param)
    return {name: run(binary, inp, tmp) for name, binary in builds.items()}


def test_preprocess_identical_with_contraction(outputs):
    cam_off, ref = outputs["off"]
    cam_fma, got = outputs["contracted"]
    assert cam_off == cam_fma, "make_camera differs between the builds"
    visible = {name: int(ref[i]["valid"].sum()) for i, name in enumerate(RUNS)}
    assert all(v > 1000 for v in visible.values()), f"too few visible splats to test anything: {visible}"
    diff = differences(ref, got)
    assert all(d == (0, 0, 0) for d in diff.values()), (
        f"(decisions, tile rects, fields) that differ with contraction on, per mode: {diff}"
    )


def test_inputs_exercise_contraction(outputs):
    """Without the guard, contraction changes decisions in the modes without dilation and the fields of every mode
    (so the test above would catch a product that escapes mul_rn)."""
    _, ref = outputs["off"]
    _, got = outputs["unguarded"]
    diff = differences(ref, got)
    assert diff["gaussian_blending"][0] > 0 and diff["analytic"][0] > 0, diff
    assert all(d[2] > 0 for d in diff.values()), diff
