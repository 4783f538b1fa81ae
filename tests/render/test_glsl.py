"""GLSL compute backend (gbviewer/render/glsl/, shaders/) against the CPU backend, plus its sort, scan, math and API.

Tolerances (GLSL vs CPU, same scene, camera and settings): mean absolute rgb difference < 1e-3 and max < 1/255 on
every pixel except threshold pixels, of which at most THRESHOLD_FRACTION (0.2%) per image are allowed.

Why there are threshold pixels at all: both backends run the same float32 formulas, but not bit-identically
(the C++ build contracts a*b+c into FMAs where g++ chooses, llvmpipe where LLVM chooses; the shaders' expf/logf
are ~1-2 ulp polynomials, glibc's are correctly rounded to ~0.5 ulp). The results differ by ~1e-7 relative, so
a decision `alpha < 1/255` (1/256), `T(1 - alpha) < 1e-4` or a ceil() of the splat radius goes the other way only
when the value lies within ~1e-6 of the cut. One flipped alpha cut costs at most ~(1/255) x colour in scalar
modes; in Gaussian Blending it also changes the window, so later splats integrate over a slightly different
window and the pixel can move by more (the float32 window cancellation described in test_render_reference.py).
Measured on llvmpipe (Mesa 22.3), 56 comparisons below: 0 pixels over 1/255 in every mode; mean differences
<= 1e-7 (scalar, mip), 6e-7 (analytic), 2e-6 (gaussian_blending); max differences 5e-5 (scalar, mip at x1),
1e-3 (analytic), 6e-4 (scalar 2x2), 2e-3 (gaussian_blending; its per-pixel evaluation counts differ on up to 37
pixels of an image, i.e. the 1e-4 stop fell one splat apart). The 0.2% bound leaves room for other drivers
(NVIDIA/AMD/Intel evaluate exp/log and contract FMAs differently) without hiding a real formula difference, which
moves most pixels of an image by more than 1/255.

`visible` and `sort_length` must match exactly up to the same kind of flip (bounded by 1e-4 of the splats).
"""

from __future__ import annotations

import importlib
import json
import math
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from helpers import front_camera, random_scene, random_view, shared_scene, skip_or_fail
from reference import MODES as REFERENCE_MODES
from test_render_reference import BACKGROUND, SCENES, _check_strict

import gbviewer as gb
from gbviewer.cli import main
from gbviewer.errors import BackendUnavailable, RenderError
from gbviewer.render import RenderSettings
from gbviewer.render.glsl import GlslRenderer, gpu, limits, shader_source, standalone_context
from gbviewer.render.glsl import context as gl_context
from gbviewer.render.glsl.sort import radix_sort, scan

pytestmark = pytest.mark.gl

REPO = Path(__file__).resolve().parents[2]
NATIVE = REPO / "native" / "include" / "gbv"
SHADERS = REPO / "shaders"

MEAN_TOL = 1e-3
MAX_TOL = 1.0 / 255.0
THRESHOLD_FRACTION = 0.002
COUNT_SLACK = 1e-4  # visible / sort_length: allowed relative difference (threshold flips, see above)

MODES = ["scalar", "mip", "analytic", "gaussian_blending", "scalar:2", "gaussian_blending:2", "wsr", "duplex"]


@pytest.fixture(scope="module")
def gl():
    """Skip (printing why) only where no OpenGL 4.3 context can be created; in CI a failure (skip_or_fail)."""
    ok, why = GlslRenderer.available()
    if not ok:
        print(f"\nglsl backend unavailable: {why}")
        skip_or_fail(why)


def compare(scene: gb.Scene, cam: gb.Camera, spec: str, renderer: GlslRenderer | None = None,
            background=(0.0, 0.0, 0.0), **options) -> dict:
    """Render with both backends; assert the tolerances of the module docstring; return the measurements."""
    settings = RenderSettings.parse(spec, background=background, **options)
    ref = gb.get_renderer(scene, "cpu").render(cam, settings)
    out = (renderer or gb.get_renderer(scene, "glsl")).render(cam, settings)
    assert out.rgb.shape == ref.rgb.shape and out.alpha.shape == ref.alpha.shape
    assert np.isfinite(out.rgb).all() and np.isfinite(out.alpha).all(), "NaN/inf in the GLSL output"
    diff = np.maximum(np.abs(out.rgb - ref.rgb).max(-1), np.abs(out.alpha - ref.alpha))
    m = {
        "mean": float(np.abs(out.rgb - ref.rgb).mean()),
        "max": float(diff.max()),
        "over": int((diff > MAX_TOL).sum()),
        "evals_differ": int((out.debug["evals"] != ref.debug["evals"]).sum()),
    }
    where = f"{scene.source} {cam.width}x{cam.height} {spec}: {m}"
    print(where)
    assert m["mean"] < MEAN_TOL, where
    assert m["over"] <= THRESHOLD_FRACTION * diff.size, where
    for key in ("visible", "sort_length"):
        a, b = getattr(out.stats, key), getattr(ref.stats, key)
        assert abs(a - b) <= COUNT_SLACK * max(b, 1), f"{where}: {key} {a} vs cpu {b}"
    return m


# ---- the port: constants, names, math ---------------------------------------------------------------------------

def _c_value(expr: str) -> float:
    expr = re.sub(r"(?<=[\d.])f\b", "", expr.strip())
    return float(eval(expr, {"__builtins__": {}}))  # literals and + - * / only


def constants(text: str, keyword: str) -> dict[str, tuple[str, float]]:
    """Top-level `keyword TYPE NAME = EXPR[, NAME = EXPR...];` declarations -> {name: (type, value)}."""
    out = {}
    for typ, body in re.findall(rf"^{keyword}\s+(float|int)\s+([^;]+);", text, re.M):
        for decl in body.split(","):
            name, _, expr = decl.partition("=")
            if "[" in name:
                raise AssertionError(f"array constant {name.strip()}: compare element-wise")
            out[name.strip()] = (typ, _c_value(expr))
    return out


def glsl_text(name: str) -> str:
    return re.sub(r"//[^\n]*", "", (SHADERS / name).read_text())


def cpp_text(name: str) -> str:
    return re.sub(r"//[^\n]*", "", (NATIVE / name).read_text())


@pytest.mark.parametrize("header, shader", [("common.h", "common.glsl"), ("preprocess.h", "preprocess.glsl")])
def test_constants_identical(header, shader):
    """Every constant of the native header (and enum value) has a GLSL constant of the same name, type and float32
    value, and the GLSL file has no others."""
    c = constants(cpp_text(header), "constexpr")
    for body in re.findall(r"^enum\s+\w+\s*:\s*\w+\s*\{([^}]*)\}", cpp_text(header), re.M):
        c.update({k.strip(): ("int", float(v)) for k, v in (e.split("=") for e in body.split(",") if e.strip())})
    g = constants(glsl_text(shader), "const")
    assert c, f"no constants parsed from {header}"
    assert set(c) == set(g), f"only in {header}: {sorted(set(c) - set(g))}; only in {shader}: {sorted(set(g) - set(c))}"
    for name, (typ, val) in c.items():
        gtyp, gval = g[name]
        assert typ == gtyp, f"{name}: {typ} in {header}, {gtyp} in {shader}"
        assert np.float32(val) == np.float32(gval), f"{name}: {val!r} in {header}, {gval!r} in {shader}"


def test_mode_values_identical():
    enum = re.search(r"enum\s+Mode\s*:\s*\w+\s*\{([^}]*)\}", cpp_text("common.h")).group(1)
    c = {k.strip(): int(v) for k, v in (e.split("=") for e in enum.split(",") if e.strip())}
    g = {k: int(v) for k, (_, v) in constants(glsl_text("common.glsl"), "const").items() if k in c}
    assert c == g == {m.name: int(m) for m in gb.Mode}


def _fields(text: str, struct: str) -> list[str]:
    body = re.search(rf"struct\s+{struct}\s*\{{([^}}]*)\}}", text).group(1)
    names = []
    for decl in body.split(";"):
        decl = re.sub(r"\[\d+\]", "", decl).strip()
        if decl:
            names += [n.strip() for n in decl.split(None, 1)[1].split(",")]
    return names


@pytest.mark.parametrize("struct", ["CameraParams", "Splat2D", "TileRect", "OitParams"])
def test_struct_fields_identical(struct):
    assert _fields(cpp_text("common.h"), struct) == _fields(glsl_text("common.glsl"), struct)


# C++ functions without a GLSL function of the same name, and why.
NOT_PORTED = {
    "blend_alpha_pixel": "the shared body of C++'s one-pixel blend_scalar / blend_analytic wrappers around the lane "
                         "templates; GLSL has those two functions themselves",
    "dot": "GLSL built-in",
    "float_bits": "GLSL built-in floatBitsToUint",
    "splat_less": "the GLSL duplex keeps each cell's member order (cells.comp), which differs from the CPU's canonical "
                  "order only by float rounding, within the tolerances above",
    "mul_rn": "GLSL declares the values that C++ multiplies through it `precise` (test_preprocess_is_not_contracted)",
    "to_fixed": "GLSL 4.30 core has no 64-bit integers: the wsr sums stay in float there (blend.glsl)",
    "tiles_outside": "duplex's cell_misses statistic, which the GLSL backend does not report",
}


def test_function_names_ported():
    """Every kernel function of native/include/gbv/*.h has a GLSL function of the same name in shaders/."""
    cpp = set()
    for h in NATIVE.glob("*.h"):
        cpp |= set(re.findall(r"^(?:GBV_HD|inline)\s+[\w:<>]+\s+(\w+)\s*\(", cpp_text(h.name), re.M))
    cpp.discard("operator")
    shader_src = "\n".join(glsl_text(p.name) for p in SHADERS.glob("*.glsl"))
    glsl_funcs = set(re.findall(r"^\w+\s+(\w+)\s*\(", shader_src, re.M))
    missing = sorted(cpp - glsl_funcs - set(NOT_PORTED))
    assert not missing, f"native functions without a GLSL port of the same name: {missing}"
    assert {"preprocess_splat", "blend_gaussian", "make_camera"} <= glsl_funcs


# Functions whose C++ products go through mul_rn (common.h): no multiply-add of theirs may be contracted.
NOT_CONTRACTED = {"make_camera", "sh_basis", "sh_to_rgb", "sh_to_weight", "covariance_3d", "project_covariance",
                  "splat_radius", "tile_rect", "view_point", "screen_footprint", "preprocess_splat", "preprocess_cell"}


@pytest.mark.parametrize("shader", ["preprocess.comp", "cells.comp"])
def test_preprocess_is_not_contracted(shader, tmp_path, monkeypatch):
    """The shaders compile (glslangValidator, OpenGL SPIR-V), and in the preprocess functions every multiply whose
    result feeds an add or subtract is `precise` together with that add (SPIR-V NoContraction on both), as the C++
    code routes those products through mul_rn: culling decisions and tile edges must not depend on whether the
    driver fuses multiply-adds (tests/render/test_fp_contract.py checks the C++ side bit for bit)."""
    exe = shutil.which("glslangValidator")
    if exe is None:
        skip_or_fail("glslangValidator (Debian: glslang-tools) is not installed")
    monkeypatch.setattr(gl_context, "SHADER_DIR", SHADERS)  # this checkout's shaders, not the installed copy
    src = tmp_path / shader
    src.write_text(shader_source(shader, {"GBV_PRECISE_MATH": 1}))
    p = subprocess.run([exe, "-G", "--aml", "-H", str(src), "-o", str(tmp_path / "out.spv")], capture_output=True,
                       text=True)
    assert p.returncode == 0, p.stdout + p.stderr
    exact = set(re.findall(r"Decorate (\d+) NoContraction", p.stdout))
    function, ops, seen, fused = None, {}, set(), []
    for line in p.stdout.splitlines():
        if m := re.match(r"\s*\d+\((\w+)\(.*\bFunction\b", line):
            function = m.group(1)
            seen.add(function)
        elif (m := re.match(r"\s*(\d+):\s+\S+\s+(FMul|FAdd|FSub|FNegate)\s+(\d+)(?:\s+(\d+))?", line)) and function:
            ident, op, args = m.group(1), m.group(2), [a for a in m.group(3, 4) if a]
            ops[ident] = op
            if op in ("FAdd", "FSub") and function in NOT_CONTRACTED:
                for a in args:
                    if ops.get(a) == "FMul" and not (ident in exact and a in exact):
                        fused.append(f"{function}: %{a} FMul -> %{ident} {op}")
    assert NOT_CONTRACTED & seen, f"none of {sorted(NOT_CONTRACTED)} found in the SPIR-V of {shader}"
    assert not fused, "multiply-adds a driver may contract:\n" + "\n".join(fused)


def _eval_glsl(fn: str, xs: np.ndarray) -> np.ndarray:
    """Evaluate the GLSL `float f(float x)` (which may call the shaders' math and blend functions) on xs."""
    ctx = standalone_context()
    src = ("#version 430\n#define GBV_PRECISE_MATH 1\n" + "".join(glsl_text(f) for f in ("common.glsl", "mathf.glsl",
           "blend.glsl")) + fn + """
layout(local_size_x = 64) in;
layout(std430, binding = 0) buffer X { float xs[]; };
void main() { uint i = gl_GlobalInvocationID.x; if (i < xs.length()) xs[i] = f(xs[i]); }
""")
    prog = ctx.compute_shader(src)
    buf = ctx.buffer(xs.astype(np.float32).tobytes())
    buf.bind_to_storage_buffer(0)
    prog.run(-(-len(xs) // 64))
    out = np.frombuffer(buf.read(), np.float32).astype(np.float64)
    buf.release()
    prog.release()
    return out


def test_math_functions(gl):
    """expf within 2 ulp and logf within 4 ulp of float64; gaussian_moment0 (A&S 7.1.26, whose erf is good to
    1.5e-7) within 1e-6 of sqrt(pi/2) erf(x/sqrt(2)): near x = 0 the formula's 1 - poly(t) e cancels, and in
    float32 that alone costs ~7e-7 (numpy float32 evaluation of the same formula: 6.7e-7)."""
    x = np.linspace(-87.0, 88.0, 200001).astype(np.float32)
    e = _eval_glsl("float f(float x) { return expf(x); }", x)
    assert np.abs(e / np.exp(x.astype(np.float64)) - 1).max() < 1.2e-7
    y = np.concatenate([np.exp(np.linspace(-80, 80, 200001)), np.linspace(0.5, 2.0, 100001)]).astype(np.float32)
    lg = _eval_glsl("float f(float x) { return logf(x); }", y)
    ref = np.log(y.astype(np.float64))
    ulp = np.spacing(np.abs(ref).astype(np.float32)).astype(np.float64)
    assert (np.abs(lg - ref) <= 4 * ulp + 1e-12).all()
    z = np.linspace(-9.0, 9.0, 100001).astype(np.float32)
    g = _eval_glsl("float f(float x) { return gaussian_moment0(x, expf(-0.5 * x * x)); }", z)
    ref = np.array([math.sqrt(math.pi / 2) * math.erf(v / math.sqrt(2)) for v in z.astype(np.float64)])
    assert np.abs(g - ref).max() < 1e-6


# ---- sort and scan ------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("n, bits, high", [(1, 4, 3), (5, 8, 4), (2049, 12, 100), (100_000, 32, 2**32),
                                           (70_000, 8, 7)])
def test_radix_sort_is_stable(gl, n, bits, high):
    r = GlslRenderer()
    rng = np.random.default_rng(n)
    keys = rng.integers(0, high, n, dtype=np.uint64).astype(np.uint32)
    bufs = [r.gpu.ensure(f"t{i}", n * 4) for i in range(4)]
    bufs[0].write(keys.tobytes())
    bufs[1].write(np.arange(n, dtype=np.uint32).tobytes())
    k, v = radix_sort(r.gpu, *bufs, n, bits)
    order = np.argsort(keys, kind="stable")
    np.testing.assert_array_equal(np.frombuffer(v.read(size=n * 4), np.uint32), order)
    np.testing.assert_array_equal(np.frombuffer(k.read(size=n * 4), np.uint32), keys[order])
    r.release()


@pytest.mark.parametrize("n", [1, 1023, 1024, 1025, 1024 * 1024 + 3])
def test_exclusive_scan(gl, n):
    r = GlslRenderer()
    data = np.random.default_rng(n).integers(0, 7, n).astype(np.uint32)
    buf = r.gpu.ensure("data", n * 4)
    buf.write(data.tobytes())
    r.gpu.ensure("totals", 64).write(np.zeros(16, np.uint32).tobytes())
    scan(r.gpu, buf, n, total_slot=0)
    expect = np.concatenate([[0], np.cumsum(data, dtype=np.uint64)[:-1]]).astype(np.uint32)
    np.testing.assert_array_equal(np.frombuffer(buf.read(size=n * 4), np.uint32), expect)
    assert np.frombuffer(r.gpu.buffers["totals"].read(size=4), np.uint32)[0] == data.sum()
    r.release()


def test_dispatch_over_two_axes(gl, monkeypatch):
    """More than 65535 groups go over x and y (scenes of > 16.7M splats); force that path with a limit of 3."""
    monkeypatch.setattr(gpu, "MAX_GROUPS", 3)
    scene = awkward_scene(6, n=4000)
    r = GlslRenderer()
    r.upload(scene)
    for spec in ("scalar", "gaussian_blending:2"):
        compare(scene, front_camera(64, 48), spec, renderer=r)
    r.release()


# ---- GLSL vs CPU --------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def bundled():
    return gb.load(gb.DEFAULT_SCENE)


@pytest.mark.parametrize("spec", MODES)
def test_bundled_scene(gl, bundled, spec):
    compare(bundled, gb.orbit_camera(bundled, 30, 20, width=128, height=96), spec, background=(0.2, 0.3, 0.4))


SHARED = ["v3dg-donut.fused.ply", "angel.compressed.ply", "biker.spz"]


@pytest.fixture(scope="module")
def shared_scenes():
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = gb.load(shared_scene(name))
        return cache[name]

    return get


@pytest.mark.parametrize("name", SHARED)
@pytest.mark.parametrize("spec", MODES)
def test_shared_scenes(gl, shared_scenes, name, spec):
    scene = shared_scenes(name)
    compare(scene, gb.orbit_camera(scene, 45, 15, width=128, height=96), spec)


def awkward_scene(seed: int, n: int = 1500, filter3d: bool = False) -> gb.Scene:
    """conftest.random_scene plus the cases that stress binning and culling: splats behind the near plane, far
    off-screen, huge (covering many tiles), degenerate (zero scale), and exact depth ties (copies of splats with
    other colours, which only the (depth, index) order of the tile lists resolves like the CPU)."""
    base = random_scene(n, seed=seed, sh_degree=3, spread=1.5)
    rng = np.random.default_rng(seed + 100)
    means, scales, quats = base.means.copy(), base.scales.copy(), base.quats.copy()
    opac, sh = base.opacities.copy(), base.sh.copy()
    k = n // 10
    means[:k, 2] = rng.uniform(-1.0, 0.25, k)  # behind / at the near plane
    means[k:2 * k, :2] = rng.uniform(-40, 40, (k, 2))  # far off-screen (Jacobian clamp)
    scales[2 * k:2 * k + 10] = rng.uniform(0.3, 1.0, (10, 3))  # huge
    scales[2 * k + 10:2 * k + 20, 0] = 0.0  # flat
    dup = rng.choice(np.arange(3 * k, n), 50, replace=False)
    means = np.concatenate([means, means[dup]])
    scales, quats = np.concatenate([scales, scales[dup]]), np.concatenate([quats, quats[dup]])
    opac = np.concatenate([opac, np.full(50, 0.9, np.float32)])
    sh = np.concatenate([sh, rng.normal(0, 1.0, sh[dup].shape).astype(np.float32)])
    f3d = rng.uniform(0.0, 0.02, len(means)) if filter3d else None
    return gb.Scene.from_arrays(means, scales, quats, opac, sh, f3d, source=f"awkward({seed}, filter3d={filter3d})")


@pytest.mark.parametrize("seed, filter3d", [(1, False), (2, True)])
@pytest.mark.parametrize("spec", MODES + ["scalar:3", "analytic:3", "gaussian_blending:3"])
def test_random_scenes(gl, seed, filter3d, spec):
    scene = awkward_scene(seed, filter3d=filter3d)
    compare(scene, front_camera(64, 48), spec, background=(1.0, 1.0, 1.0))


@pytest.mark.parametrize("spec", MODES)
def test_orthographic_cameras(gl, bundled, spec):
    """Orthographic cameras: the bundled scene's orthographic orbit, and the awkward scene seen orthographically."""
    compare(bundled, gb.orbit_camera(bundled, 30, 20, width=128, height=96, projection="orthographic"), spec,
            background=(0.2, 0.3, 0.4))
    compare(awkward_scene(4), front_camera(64, 48).with_projection("orthographic", 4.0), spec)


@pytest.mark.parametrize("supersample", [1, 2])
@pytest.mark.parametrize("mode", REFERENCE_MODES)
@pytest.mark.parametrize("seed,sh_degree,filter3d", SCENES[1:3])
def test_orthographic_matches_reference(gl, mode, supersample, seed, sh_degree, filter3d):
    """The GLSL backend against the float64 reference directly, with test_render_reference.py's strict tolerance
    (measured: <= 5e-6 off ties in every mode, as in perspective)."""
    scene, cam = random_view(seed, sh_degree=sh_degree, filter3d=filter3d, projection="orthographic")
    frame = gb.get_renderer(scene, "glsl").render(cam, RenderSettings(gb.Mode.parse(mode), supersample, BACKGROUND))
    _check_strict(frame, scene, cam, mode, supersample)


def test_odd_sizes_and_off_centre(gl):
    """Image sizes that are not multiples of 16 (partial tiles, N=3 blocks past the tile grid), fx != fy."""
    scene = awkward_scene(3)
    cam = gb.Camera(37, 29, 40.0, 33.0, 15.2, 16.9, np.eye(3), np.zeros(3))
    for spec in ("scalar", "gaussian_blending", "mip:3", "gaussian_blending:5"):
        compare(scene, cam, spec)


def test_long_tile_lists(gl):
    """One tile with a list longer than llvmpipe's 65535 loop iterations per invocation: every splat is evaluated
    (the blend is split over dispatches there), as on the CPU. Faint sub-pixel splats, so most pixels never
    terminate."""
    rng = np.random.default_rng(7)
    n = 70_000
    means = np.stack([rng.uniform(-0.25, 0.25, n), rng.uniform(-0.25, 0.25, n), rng.uniform(2.0, 3.0, n)], 1)
    scene = gb.Scene.from_arrays(means, np.full((n, 3), 0.002), rng.normal(size=(n, 4)), rng.uniform(0.01, 0.3, n),
                                 rng.uniform(-1, 1, (n, 1, 3)), source="long lists")
    cam = front_camera(16, 16, 30.0)
    compare(scene, cam, "scalar")
    out = gb.get_renderer(scene, "glsl").render(cam, RenderSettings.parse("scalar"))
    ref = gb.get_renderer(scene, "cpu").render(cam, RenderSettings.parse("scalar"))
    assert out.stats.sort_length == out.stats.visible > 65535
    assert out.debug["evals"].max() == out.stats.sort_length
    np.testing.assert_array_equal(out.debug["evals"], ref.debug["evals"])


@pytest.mark.parametrize("spec", ["scalar", "gaussian_blending", "analytic:2", "gaussian_blending:3", "wsr",
                                  "duplex:2"])
def test_blend_split_over_dispatches(gl, monkeypatch, spec):
    """The multi-dispatch blend (groups of render tiles, windows of the lists, state kept in buffers) that drivers
    with a loop cap need, forced here with a cap of 2000 iterations (lists of 768 splats per dispatch)."""
    renderer = GlslRenderer()
    monkeypatch.setitem(limits._loop_limits, renderer.ctx, 2000)
    assert len(limits.plan_blend(3, 5000, 2000)) == 9 * 7
    scene = awkward_scene(8, n=6000)
    renderer.upload(scene)
    compare(scene, front_camera(48, 32), spec, renderer=renderer)
    renderer.release()


def test_order_independent_options(gl):
    """wsr and duplex with trained view weights, depth correction, other E and cell sizes, supersampling; the GLSL
    backend sums the weights in float in list order, the CPU in fixed point (same values to ~1e-7)."""
    base = awkward_scene(9, n=2000)
    rng = np.random.default_rng(9)
    vw = rng.normal(0.0, 0.3, (base.num_splats, 9))
    vw[:, 0] = rng.uniform(-0.3, 3.0, base.num_splats)
    scene = gb.Scene.from_arrays(base.means, base.scales, base.quats, base.opacities, base.sh, view_weight_sh=vw,
                                 wsr_sigma=5.0, weight_background=0.1)
    r = GlslRenderer()
    r.upload(scene)
    cam = front_camera(64, 48)
    for spec, opts in [("wsr", {"depth_correct": True}), ("wsr:2", {}), ("duplex", {"depth_correct": True}),
                       ("duplex:3", {"et_grade": 1.5, "cell_size": 3}), ("duplex", {"cell_size": 9})]:
        m = compare(scene, cam, spec, renderer=r, background=(0.3, 0.2, 0.1), **opts)
        assert m["max"] < 1e-3, (spec, opts, m)
    r.release()


def test_wsr_huge_view_weights(gl):
    """View weights of 10^6..10^9: both backends cap alpha and each weighted colour at WSR_FIXED_MAX (the CPU's
    int64 fixed-point bound), so they weigh the splats alike (uncapped float sums would not match the CPU)."""
    base = awkward_scene(10, n=1500)
    vw = np.zeros((base.num_splats, 4))
    vw[:, 0] = np.random.default_rng(10).uniform(1e6, 1e9, base.num_splats)
    scene = gb.Scene.from_arrays(base.means, base.scales, base.quats, base.opacities, base.sh, view_weight_sh=vw,
                                 weight_background=0.5)
    for spec in ("wsr", "wsr:2"):
        m = compare(scene, front_camera(64, 48), spec, background=(0.3, 0.2, 0.1))
        assert m["max"] < 1e-3, (spec, m)


def test_debug_planes(gl, bundled):
    cam = gb.orbit_camera(bundled, width=64, height=48)
    s = RenderSettings.parse("gaussian_blending:2", debug="window")
    ref = gb.get_renderer(bundled, "cpu").render(cam, s)
    out = gb.get_renderer(bundled, "glsl").render(cam, s)
    assert out.debug["window"].shape == (48, 64, 2) and out.debug["evals"].dtype == np.int32
    assert np.abs(out.debug["window"] - ref.debug["window"]).mean() < 1e-3
    assert abs(out.stats.evaluations - ref.stats.evaluations) <= 1e-3 * ref.stats.evaluations
    assert out.stats.evals_per_pixel == pytest.approx(out.stats.evaluations / (cam.width * cam.height))
    assert out.stats.total_ms > 0 and min(out.stats.preprocess_ms, out.stats.sort_ms, out.stats.blend_ms) >= 0
    assert out.stats.backend == "glsl" and out.stats.mode == s.label


# ---- buffers, scenes, contexts ------------------------------------------------------------------------------------

def test_buffers_reused_and_grown(gl):
    small, large = awkward_scene(4, n=300), awkward_scene(5, n=3000)
    cam, s = front_camera(64, 48), RenderSettings()
    r = GlslRenderer()
    r.upload(small)
    r.render(cam, s)
    first = r.allocations
    r.render(cam, s)
    assert r.allocations == first, "the second identical frame reallocated buffers"
    r.upload(large)  # a larger scene after a smaller one: buffers grow ...
    compare(large, cam, "scalar", renderer=r)
    compare(large, cam, "gaussian_blending", renderer=r)
    grown = r.allocations
    assert grown > first
    r.upload(small)  # ... and a smaller one reuses them
    compare(small, cam, "scalar", renderer=r)
    assert r.allocations == grown
    r.release()


def test_empty_frame(gl):
    scene = random_scene(50)
    cam = gb.Camera(32, 32, 30, 30, 16, 16, np.eye(3), [0.0, 0.0, -10.0])  # every splat behind the camera
    out = GlslRenderer()
    out.upload(scene)
    f = out.render(cam, RenderSettings(background=(0.5, 0.25, 1.0)))
    assert f.stats.visible == 0 and f.stats.sort_length == 0
    np.testing.assert_array_equal(f.rgb, np.broadcast_to(np.float32([0.5, 0.25, 1.0]), (32, 32, 3)))
    assert (f.alpha == 0).all() and (f.debug["evals"] == 0).all()


def test_existing_context(gl, bundled):
    """An app passes its moderngl.Context (kept current in its thread); the renderer works in it."""
    ctx = standalone_context()  # stands in for the app's window context,
    with ctx:  # which the app keeps current in its thread
        r = GlslRenderer(ctx=ctx)
        r.upload(bundled)
        cam, s = gb.orbit_camera(bundled, width=48, height=40), RenderSettings.parse("gaussian_blending")
        frame = r.render(cam, s)
        ref = gb.get_renderer(bundled, "cpu").render(cam, s)
        assert np.abs(frame.rgb - ref.rgb).mean() < MEAN_TOL
        assert np.abs(frame.rgb - ref.rgb).max() < MAX_TOL
        r.release()


def test_unavailable_is_clear(monkeypatch):
    monkeypatch.setattr(gl_context, "_standalone", {})
    monkeypatch.setattr(importlib.import_module("gbviewer.render.registry"), "_renderers", {})  # none made while GL was there

    def no_egl():
        raise Exception("eglInitialize failed (0x3001)")

    monkeypatch.setattr(gl_context, "_new_context", no_egl)
    ok, why = GlslRenderer.available()
    assert not ok and "eglInitialize failed" in why and "OpenGL 4.3" in why and "libegl1" in why
    with pytest.raises(BackendUnavailable, match="eglInitialize failed"):
        GlslRenderer()
    with pytest.raises(BackendUnavailable, match="glsl backend unavailable"):
        gb.render(random_scene(10), front_camera(), backend="glsl")

    class OldContext:
        version_code = 410
        info = {"GL_RENDERER": "Old GPU"}

    with pytest.raises(BackendUnavailable, match=r"OpenGL 4\.1 \(Old GPU\).*4\.3"):
        GlslRenderer(ctx=OldContext())
    assert GlslRenderer.check_context(OldContext())[0] is False


def test_scene_too_large_is_clear(gl):
    r = GlslRenderer()
    r.gpu.max_block = 4096  # pretend a GPU whose storage buffers hold 4 KiB
    with pytest.raises(RenderError, match="GL_MAX_SHADER_STORAGE_BLOCK_SIZE"):
        r.upload(random_scene(200))


# ---- command line -------------------------------------------------------------------------------------------------

def test_cli_render_glsl(gl, tmp_path):
    npy = tmp_path / "g.npy"
    args = [str(gb.DEFAULT_SCENE), "--width", "64", "--height", "48", "--mode", "gaussian_blending", "--out"]
    assert main(["render", *args, str(npy), "--backend", "glsl"]) == 0
    scene = gb.load(gb.DEFAULT_SCENE)
    ref = gb.render(scene, gb.orbit_camera(scene, width=64, height=48), "gaussian_blending").rgb
    assert np.abs(np.load(npy) - ref).max() < MAX_TOL


def test_cli_bench_cpu_and_glsl(gl, tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(["bench", str(gb.DEFAULT_SCENE), "--backends", "cpu,glsl", "--modes", "scalar,gaussian_blending",
                 "--views", "1", "--repeat", "1", "--size", "64x48", "--rates", "1,1/2", "--json", str(out)]) == 0
    doc = json.loads(out.read_text())
    rows = [r for r in doc["speed"] if r["backend"] == "glsl"]
    assert len(rows) == 4 and all(r["visible"] > 0 for r in rows)
    assert "OpenGL" in doc["machine"]["glsl_backend"]
    assert any(r["backend"] == "glsl" and r["ratio"] == "gaussian_blending / scalar" for r in doc["ratios"])


def test_headless_renderer_survives_another_current_context(gl, bundled):
    """Another context made current in this thread (an app window, say) must not receive the renderer's work."""
    import moderngl

    cam = gb.orbit_camera(bundled, width=48, height=40)
    r = GlslRenderer()
    r.upload(bundled)
    other = moderngl.create_context(standalone=True, backend="egl")  # current from here on
    try:
        frame = r.render(cam, RenderSettings())
        other.clear(0.0, 0.0, 0.0)  # the other context still works
    finally:
        other.release()
    ref = gb.get_renderer(bundled, "cpu").render(cam, RenderSettings())
    assert frame.stats.visible == ref.stats.visible > 0
    assert np.abs(frame.rgb - ref.rgb).max() < MAX_TOL
