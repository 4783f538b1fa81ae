"""Every Python that pyproject.toml's requires-python claims (3.11, 3.12, 3.13), beside the one running the suite
(slow; CI runs it): the CPU module built for that Python (its own venv, cached, with the package's dependencies and the
test tools from the package index), then a part of the suite run there against it: the camera and dataclass
equality (Python 3.13 compares dataclass fields one by one), loading and rendering on every backend's contract."""

from __future__ import annotations

import glob
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from helpers import HOST_ONLY, skip_or_fail
from native_builds import CACHE, ROOT, build, cmake_env, configure, hidden_highway

PYTHONS = ("3.11", "3.12", "3.13")
TESTS = [
    "tests/model/test_camera.py",
    "tests/test_dataclass_equality.py",
    "tests/model/test_keyframes.py",
    "tests/io/test_inria_ply.py",
    "tests/render/test_render.py",
]

pytestmark = [
    pytest.mark.slow,
    HOST_ONLY,
    pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is not installed"),
]


def test_requires_python_states_what_is_tested():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert project["project"]["requires-python"] == f">={PYTHONS[0]}"
    tags = project["tool"]["cibuildwheel"]["build"].split()
    assert tags == [f"cp{v.replace('.', '')}-*" for v in PYTHONS]


def interpreter(version: str) -> str | None:
    """A CPython `version` that runs on this machine: one of pyenv's, or one on PATH (a pyenv shim of a version
    that is not selected exits 127: not counted)."""
    pyenv = sorted(glob.glob(str(Path.home() / f".pyenv/versions/{version}.*/bin/python{version}")))
    for candidate in [*pyenv[::-1], shutil.which(f"python{version}")]:
        if candidate and subprocess.run([candidate, "-c", "import venv"], capture_output=True).returncode == 0:
            return candidate
    return None


def venv_for(python: str, version: str) -> Path:
    """A venv of `python` with the package's dependencies, the viewer extra and the test tools (kept in the cache)."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    wanted = [
        *project["dependencies"],
        *project["optional-dependencies"]["viewer"],
        "pytest",
        "hypothesis",
        "scipy",
        "nanobind",
    ]
    venv = CACHE / "pythons" / version
    stamp = venv / "gbviewer-requirements.txt"
    if not stamp.exists() or stamp.read_text() != "\n".join(wanted):
        shutil.rmtree(venv, ignore_errors=True)
        subprocess.run([python, "-m", "venv", str(venv)], check=True, timeout=300)
        proc = subprocess.run(
            [str(venv / "bin" / "python"), "-m", "pip", "install", "-q", *wanted],
            capture_output=True,
            text=True,
            timeout=1200,
        )
        if proc.returncode:
            skip_or_fail(f"could not install the dependencies for Python {version}: {proc.stderr.strip()[-500:]}")
        stamp.write_text("\n".join(wanted))
    return venv / "bin" / "python"


@pytest.mark.parametrize("version", [v for v in PYTHONS if v != "%d.%d" % sys.version_info[:2]])
def test_the_suite_part_passes_on(version, tmp_path):
    python = interpreter(version)
    if python is None:
        skip_or_fail(f"no Python {version} on this machine (PATH or ~/.pyenv)")
    vpython = venv_for(python, version)
    b = tmp_path / "b"
    proc = configure(b, *hidden_highway(), python=str(vpython))  # the pinned Highway, as a user without libhwy-dev
    assert proc.returncode == 0, proc.stdout + proc.stderr
    module = build(b)
    assert f"cpython-{version.replace('.', '')}" in module.name
    work = tmp_path / "checkout"
    for part in ("gbviewer", "shaders", "assets", "tests", "tools"):
        shutil.copytree(ROOT / part, work / part, ignore=shutil.ignore_patterns("_native*", "__pycache__"))
    shutil.copy2(ROOT / "pyproject.toml", work)
    if (ROOT.parent / "shared").is_dir():  # the shared scenes beside the checkout, as beside this one
        (tmp_path / "shared").symlink_to(ROOT.parent / "shared")
    shutil.copy2(module, work / "gbviewer" / module.name)
    env = {k: v for k, v in cmake_env().items() if not k.startswith(("PYTHON", "VIRTUAL_ENV"))}
    env["PYTHONPATH"] = str(work)  # the staged package, for the tests' own child processes too
    proc = subprocess.run(
        [str(vpython), "-m", "pytest", "-q", "-p", "no:cacheprovider", *TESTS],
        cwd=work,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    summary = proc.stdout.strip().splitlines()[-1] if proc.stdout.strip() else proc.stderr[-2000:]
    assert proc.returncode == 0 and " passed" in summary, proc.stdout[-4000:] + proc.stderr[-2000:]
