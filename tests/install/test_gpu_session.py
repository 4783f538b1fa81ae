"""bench/gpu_session.sh without a GPU (so that the one prepared GPU session cannot rot between GPUs): it writes its
text and JSON report with "no GPU" for every CUDA piece and still runs the GLSL pieces, on a clone where nothing is
installed too; it finds every file it would run, and the test files it and bench/cuda_check.py run import and
collect."""

from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import gbviewer as gb

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "bench"))
from gpu_session import CUDA_PIECES, CUDA_TEST_FILES, GLSL_TEST_FILES, MODES, PIECES  # noqa: E402

QUICK = "glsl vs cpu,display path + interop"  # the GLSL pieces that take seconds on llvmpipe


def run_session(repo: Path, out: Path, env: dict, *args: str) -> tuple[subprocess.CompletedProcess, dict]:
    proc = subprocess.run(
        ["bash", str(repo / "bench" / "gpu_session.sh"), str(out), *args],
        capture_output=True,
        text=True,
        timeout=150,
        env=dict(env, GBV_SESSION_SECONDS="120"),
    )
    report = json.loads((out / "report.json").read_text()) if (out / "report.json").exists() else {"pieces": []}
    text = (out / "report.txt").read_text().splitlines() if (out / "report.txt").exists() else []
    assert [line.split(":")[0] for line in text[: len(report["pieces"])]] == [p["name"] for p in report["pieces"]]
    return proc, {p["name"]: p for p in report["pieces"]}


def assert_no_gpu_report(pieces: dict, why: str) -> None:
    """CUDA pieces say why they did not run; of the GLSL ones, QUICK ran and passed, the rest were not selected."""
    assert set(pieces) == {"build", "paths", *PIECES}, pieces
    assert pieces["paths"]["status"] == "ok", pieces["paths"]  # every test file found, scenes found
    assert pieces["build"]["status"] == "no GPU", pieces["build"]
    for name in CUDA_PIECES:
        assert pieces[name]["status"].startswith(f"no GPU: {why}"), pieces[name]
    for name in set(PIECES) - set(CUDA_PIECES):
        expected = "ok" if name in QUICK.split(",") else "skipped: not selected (--pieces)"
        assert pieces[name]["status"] == expected, pieces[name]
    assert "cuda interop: no GPU" in pieces["display path + interop"]["detail"]


def test_no_gpu_session_runs_the_glsl_pieces(tmp_path):
    scenes = gb.DEFAULT_SCENE.parent
    env = dict(os.environ, PYTHON=sys.executable)
    proc, pieces = run_session(REPO, tmp_path / "out", env, str(scenes), "--no-gpu", "--pieces", QUICK)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert_no_gpu_report(pieces, "--no-gpu given")
    assert f"scenes: {scenes}" in pieces["paths"]["detail"]
    assert len(pieces["glsl vs cpu"]["data"]) == len(MODES)  # every mode on the bundled scene


def test_session_on_a_clone_with_nothing_installed(tmp_path):
    """A copy of the checkout's tracked files, python3 with no site-packages at all and no .venv: the session makes
    its own venv and installs gbviewer[dev] into it, then runs what needs no GPU and exits 0. The venv and pip are
    stand-ins (a real install builds the module for minutes): the venv's python is this interpreter, and pip puts
    this build's compiled module into the copy, as an editable install would."""
    clone = tmp_path / "clone"
    files = subprocess.run(["git", "ls-files", "-z"], cwd=REPO, capture_output=True, check=True).stdout
    for rel in filter(None, files.decode().split("\0")):
        if (REPO / rel).is_file():
            (clone / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / rel, clone / rel)
    native = sorted(Path(gb.__file__).parent.glob("_native.*"))
    assert native, "the test needs the built CPU module"
    bare = sys.executable + " -S"  # no site-packages: nothing installed (numpy included)
    pip_log = tmp_path / "pip-args.txt"
    venv_python = f"""#!/bin/bash
if [ "$1 $2" = "-m pip" ]; then echo "$*" >> {pip_log}; cp {native[0]} {clone}/gbviewer/; exit 0; fi
exec {sys.executable} "$@"
"""
    python3 = tmp_path / "bin" / "python3"
    python3.parent.mkdir()
    python3.write_text(f"""#!/bin/bash
if [ "$1 $2" = "-m venv" ]; then mkdir -p "$3/bin" && cat > "$3/bin/python" <<'EOF'
{venv_python}EOF
chmod +x "$3/bin/python"; exit 0; fi
exec {bare} "$@"
""")
    python3.chmod(python3.stat().st_mode | stat.S_IXUSR)
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHON", "GBV_WHEELHOUSE", "VIRTUAL_ENV")}
    env["PATH"] = f"{python3.parent}:{env['PATH']}"
    proc, pieces = run_session(clone, tmp_path / "out", env, str(clone / "assets"), "--no-gpu", "--pieces", QUICK)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    assert "lacks numpy" in proc.stdout and f"installing gbviewer[dev] into {clone}/.venv" in proc.stdout, proc.stdout
    assert f"{clone}[dev]" in pip_log.read_text()
    assert_no_gpu_report(pieces, "--no-gpu given")


def test_the_sessions_test_files_collect():
    files = [*CUDA_TEST_FILES, *GLSL_TEST_FILES]
    assert all((REPO / f).is_file() for f in files), [f for f in files if not (REPO / f).is_file()]
    proc = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "--collect-only", "-p", "no:cacheprovider", *files],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 0 and " collected" in proc.stdout, proc.stdout[-2000:] + proc.stderr


def test_cuda_check_finds_its_test_files():
    """bench/cuda_check.py imports the session's list (its own once pointed at a moved file); without a device it
    stops with one line."""
    proc = subprocess.run(
        [sys.executable, str(REPO / "bench" / "cuda_check.py")], capture_output=True, text=True, timeout=60
    )
    from gbviewer.render import CudaRenderer

    if not CudaRenderer.available()[0]:
        assert proc.returncode == 1 and proc.stdout.startswith("CUDA backend unavailable:"), proc.stdout + proc.stderr
