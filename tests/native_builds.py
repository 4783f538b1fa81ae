"""Helpers of the build tests (test_build_info, test_build_variants, test_aarch64): configure and build the CPU module
with CMake, run a built module in a child Python beside a copy of this checkout's gbviewer package, and compare its
renders with this process's."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import tarfile
import urllib.request
from pathlib import Path

import numpy as np
from helpers import skip_or_fail

import gbviewer as gb
from gbviewer import _native

ROOT = Path(__file__).resolve().parents[1]
# five of the six modes; analytic is left to test_simd*.py's NEON tests (its renders are ~50x slower under emulation)
MODES = ("scalar", "mip", "gaussian_blending", "wsr", "duplex")
# Tolerance between two builds' renders (another compiler, FMA contraction, libm, another vector width): as
# simd_helpers.py's between a vector path and the scalar one, colours and alphas within TOL but for pixels where an
# alpha or transmittance cut went the other way (at most FLIP_FRACTION of the pixels plus 2, each within FLIP_MAX).
TOL, FLIP_FRACTION, FLIP_MAX = 1e-5, 2e-3, 2e-2

# The child: build_info and, per scene and mode, rgb+alpha rendered on the module's default path.
CHILD = r"""
import json, sys, numpy as np, gbviewer as gb
out, size, scenes = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
res = {"build": gb.build_info(), "simd": []}
for i, path in enumerate(scenes):
    scene = gb.load(path)
    cam = gb.orbit_camera(scene, 30, 20, width=size, height=size * 3 // 4)
    for mode in %r:
        f = gb.render(scene, cam, mode=mode)
        np.save(f"{out}/{i}-{mode}.npy", np.dstack([f.rgb, f.alpha]))
        res["simd"].append(f.stats.simd)
print(json.dumps(res))
""" % (MODES,)


def compile_check(source: Path, exe: Path, includes: list[Path], optimise: bool = True) -> None:
    """Build a standalone C++ check (`source`, beside its test) with warnings as errors into `exe`: a missing compiler
    skips (fails in CI), a failed build fails with the compiler's message."""
    cxx = shutil.which("c++") or shutil.which("g++") or shutil.which("clang++")
    if cxx is None:
        skip_or_fail("no C++ compiler (c++, g++ or clang++)")
    flags = ["-std=c++17", *(["-O1"] if optimise else []), "-Wall", "-Wextra", "-Werror"]
    cmd = [cxx, *flags, *(f"-I{p}" for p in includes), str(source), "-o", str(exe)]
    build = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert build.returncode == 0, build.stderr[-3000:]


def cmake_env(**extra: str) -> dict[str, str]:
    """This environment for a configure, without the switches the tests set themselves, plus `extra`."""
    drop = ("GBVIEWER_SCALAR_ONLY", "GBVIEWER_FETCH_HIGHWAY", "GBVIEWER_HIGHWAY_ARCHIVE", "GBVIEWER_SIMD")
    return {**{k: v for k, v in os.environ.items() if k not in drop}, **extra}


def configure(
    build: Path, *args: str, env: dict[str, str] | None = None, python: str = sys.executable
) -> subprocess.CompletedProcess:
    """`cmake -S ROOT -B build` for the CPU module alone (no CUDA), with `python` (this one) and its nanobind; ccache
    when installed (the build tests rebuild the same sources)."""
    nb_dir = subprocess.check_output([python, "-m", "nanobind", "--cmake_dir"], text=True).strip()
    gen = ["-G", "Ninja"] if shutil.which("ninja") else []
    cache = ["-DCMAKE_CXX_COMPILER_LAUNCHER=ccache"] if shutil.which("ccache") else []
    cmd = [
        "cmake",
        "-S",
        str(ROOT),
        "-B",
        str(build),
        *gen,
        *cache,
        "-DGBVIEWER_CUDA=OFF",
        f"-Dnanobind_DIR={nb_dir}",
        f"-DPython_EXECUTABLE={python}",
        "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON",
        *args,
    ]
    return subprocess.run(cmd, capture_output=True, text=True, env=env or cmake_env(), timeout=300)


def build(build_dir: Path) -> Path:
    """Build the module alone (two jobs) and return its file."""
    proc = subprocess.run(
        ["cmake", "--build", str(build_dir), "-j2", "--target", "_native"], capture_output=True, text=True, timeout=900
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return next(build_dir.glob("_native.*"))


def hidden_highway() -> list[str]:
    """CMake arguments under which installed Highway headers are not found: their include directory ignored."""
    dirs = [d for d in ("/usr/include", "/usr/local/include") if (Path(d) / "hwy/highway.h").exists()]
    return [f"-DCMAKE_IGNORE_PATH={';'.join(dirs)}"] if dirs else []


# Highway releases a user can have beside the pinned 1.0.3 (Debian 12): 1.1, 1.2 (Debian 13) and the newest. Each
# SHA-256 is GitHub's release tarball's, as Homebrew's and Spack's recipes pin it; Debian's orig tarballs are the same
# bytes where Debian has the release.
HIGHWAY_RELEASES = {
    "1.1.0": "354a8b4539b588e70b98ec70844273e3f2741302c4c377bcc4e81b3d1866f7c9",
    "1.2.0": "7e0be78b8318e8bdbf6fa545d2ecb4c90f947df03f7aadc42c1967f019e63343",
    "1.3.0": "07b3c1ba2c1096878a85a31a5b9b3757427af963b1141ca904db2f9f4afe0bc2",
}
CACHE = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "gbviewer"


def fetch_highway(version: str, dest: Path) -> Path | str:
    """Highway `version`'s headers unpacked under dest (its include directory), the tarball kept in the user's cache
    once its SHA-256 matched; or, where no source gives it, why (a string)."""
    archive = CACHE / "highway" / f"highway-{version}.tar.gz"
    tried = []
    for url in (
        f"https://github.com/google/highway/archive/refs/tags/{version}.tar.gz",
        f"https://deb.debian.org/debian/pool/main/h/highway/highway_{version}.orig.tar.gz",
    ):
        if archive.exists() and hashlib.sha256(archive.read_bytes()).hexdigest() == HIGHWAY_RELEASES[version]:
            break
        archive.parent.mkdir(parents=True, exist_ok=True)
        try:
            with urllib.request.urlopen(url, timeout=60) as reply:
                data = reply.read(64 << 20)
        except OSError as exc:
            tried.append(f"{url} ({exc})")
            continue
        if hashlib.sha256(data).hexdigest() != HIGHWAY_RELEASES[version]:
            tried.append(f"{url} (SHA-256 mismatch)")
            continue
        archive.with_suffix(".part").write_bytes(data)
        archive.with_suffix(".part").replace(archive)
    else:
        if not archive.exists():
            return f"Highway {version} could not be fetched: {'; '.join(tried)}"
    with tarfile.open(archive) as tar:
        tar.extractall(
            dest, members=[m for m in tar.getmembers() if m.name.startswith(f"highway-{version}/hwy/")], filter="data"
        )
    return dest / f"highway-{version}"


def stage_package(module: Path, dest: Path) -> Path:
    """dest/gbviewer: this checkout's package with `module` as its _native (and shaders/ beside it, as in a
    checkout), for a child Python whose PYTHONPATH is dest."""
    shutil.copytree(ROOT / "gbviewer", dest / "gbviewer", ignore=shutil.ignore_patterns("_native*", "__pycache__"))
    shutil.copytree(ROOT / "shaders", dest / "shaders")
    shutil.copy2(module, dest / "gbviewer" / module.name)
    return dest


def run_child(
    python: list[str], pkg: Path, out: Path, scenes: list[Path], size: int, env: dict[str, str], timeout: float
) -> dict:
    """Run CHILD with `python` (a command: an interpreter, or qemu and one) on pkg; its report."""
    out.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run(
        [*python, "-c", CHILD, str(out), str(size), *map(str, scenes)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd="/",
        env={**env, "PYTHONPATH": str(pkg)},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def assert_renders_match(out: Path, scenes: list[Path], size: int, path: str, what: str) -> None:
    """The child's images in `out` against this process's on SIMD path `path`, within the stated tolerance."""
    before = _native.simd()
    _native.testing.set_simd(path)
    try:
        for i, scene_path in enumerate(scenes):
            scene = gb.load(scene_path)
            cam = gb.orbit_camera(scene, 30, 20, width=size, height=size * 3 // 4)
            for mode in MODES:
                f = gb.render(scene, cam, mode=mode)
                here = np.dstack([f.rgb, f.alpha])
                there = np.load(out / f"{i}-{mode}.npy")
                diff = np.abs(there - here).max(axis=2)
                flips = int((diff > TOL).sum())
                allowed = 2 + FLIP_FRACTION * diff.size
                label = f"{what}: {scene_path.name} {mode}"
                assert flips <= allowed, f"{label}: {flips} pixels beyond {TOL} (allowed {allowed:.0f})"
                assert diff.max() <= FLIP_MAX, f"{label}: max difference {diff.max():.2e}"
    finally:
        _native.testing.set_simd(before)
