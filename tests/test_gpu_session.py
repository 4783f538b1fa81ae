"""bench/gpu_session.sh in its no-GPU mode (so that the one prepared GPU session cannot rot between GPUs): it
writes its text and JSON report with "no GPU" for every GPU piece, finds every file it would run, and the test
files it and bench/cuda_check.py run import and collect."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import gbviewer as gb
from helpers import SHARED_SCENES

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "bench"))
from gpu_session import CUDA_TEST_FILES, GLSL_TEST_FILES  # noqa: E402

GPU_PIECES = {"build", "cuda tests", "cuda vs cpu", "glsl on the EGL driver", "glsl vs cpu", "display path + interop",
              "timings"}


def test_no_gpu_session_reports_every_piece(tmp_path):
    scenes = SHARED_SCENES if SHARED_SCENES.is_dir() else gb.DEFAULT_SCENE.parent
    env = dict(os.environ, PYTHON=sys.executable, GBV_SESSION_SECONDS="60")
    proc = subprocess.run(["bash", str(REPO / "bench" / "gpu_session.sh"), str(tmp_path / "out"), str(scenes),
                           "--no-gpu"], capture_output=True, text=True, timeout=60, env=env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    pieces = {p["name"]: p for p in report["pieces"]}
    assert set(pieces) == GPU_PIECES | {"paths"}, pieces
    assert pieces["paths"]["status"] == "ok", pieces["paths"]  # every test file found, scenes found
    assert f"scenes: {scenes}" in pieces["paths"]["detail"]
    for name in GPU_PIECES:
        assert pieces[name]["status"].startswith("no GPU"), pieces[name]
    text = (tmp_path / "out" / "report.txt").read_text().splitlines()
    assert [line.split(":")[0] for line in text] == [p["name"] for p in report["pieces"]]


def test_the_sessions_test_files_collect():
    files = [*CUDA_TEST_FILES, *GLSL_TEST_FILES]
    assert all((REPO / f).is_file() for f in files), [f for f in files if not (REPO / f).is_file()]
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "--collect-only", "-p", "no:cacheprovider", *files],
                          cwd=REPO, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and " collected" in proc.stdout, proc.stdout[-2000:] + proc.stderr


def test_cuda_check_finds_its_test_files():
    """bench/cuda_check.py imports the session's list (its own once pointed at a moved file); without a device it
    stops with one line."""
    proc = subprocess.run([sys.executable, str(REPO / "bench" / "cuda_check.py")], capture_output=True, text=True,
                          timeout=60)
    from gbviewer.render import CudaRenderer

    if not CudaRenderer.available()[0]:
        assert proc.returncode == 1 and proc.stdout.startswith("CUDA backend unavailable:"), proc.stdout + proc.stderr
