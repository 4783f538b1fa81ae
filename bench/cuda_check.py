"""Run on a machine with an NVIDIA GPU: the CUDA test files, then the CPU/CUDA speed table.

    bash scripts/setup.sh            # builds gbviewer._native_cuda when nvcc is on PATH
    .venv/bin/python bench/cuda_check.py [SCENE ...]

bench/gpu_session.sh is the fuller session (CUDA vs CPU on every mode and scene, GLSL on the GPU's driver, the
display path, timings, one report). Exits non-zero when the CUDA backend is unavailable or a test fails."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from gpu_session import CUDA_TEST_FILES

import gbviewer as gb
from gbviewer.render import CudaRenderer

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str]) -> int:
    ok, why = CudaRenderer.available()
    if not ok:
        print(f"CUDA backend unavailable: {why}")
        return 1
    from gbviewer._native_cuda import availability

    print(f"CUDA device: {availability()[1]}")
    tests = subprocess.run([sys.executable, "-m", "pytest", "-q", *CUDA_TEST_FILES], cwd=REPO)
    if tests.returncode != 0:
        return tests.returncode
    scenes = argv or [str(gb.DEFAULT_SCENE)]
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "gbviewer",
            "bench",
            *scenes,
            "--backends",
            "cpu,cuda",
            "--modes",
            "scalar,mip,analytic,gaussian_blending,supersample:3",
            "--size",
            "800x800",
            "--views",
            "3",
            "--repeat",
            "10",
            "--rates",
            "1,1/2,1/4,1/8",
        ]
    ).returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
