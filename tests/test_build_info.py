"""Never silently slow (issue 26): gb.build_info() and `gbviewer info` report the CPU module's build; a configure
where Highway's headers are not found fails with one line naming the package and the switch; the scalar-only switch
configures (and builds, slow) a module that reports it."""

from __future__ import annotations

import json
import os
import platform
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import gbviewer as gb
from gbviewer import _native
from gbviewer.cli import main
from gbviewer.render import simd_line

ROOT = Path(__file__).resolve().parents[1]
X86 = platform.machine() in ("x86_64", "AMD64")
NO_HWY_LINE = "gbviewer: Google Highway's headers (hwy/highway.h) not found"


def cpu_flags() -> set[str]:
    """This CPU's feature flags (/proc/cpuinfo), to know which paths the module must offer here."""
    text = Path("/proc/cpuinfo").read_text() if Path("/proc/cpuinfo").exists() else ""
    line = next((ln for ln in text.splitlines() if ln.startswith("flags")), "")
    return set(line.split(":", 1)[-1].split())


def test_build_info_matches_the_module():
    info = gb.build_info()
    assert info["cpu_module"] is True
    assert info["simd_usable"] == _native.simd_paths() and info["simd_selected"] == _native.simd()
    assert set(info["simd_usable"]) <= set(info["simd_built"]) and info["simd_built"][0] == "scalar"
    assert info["openmp"] and info["compiler"] and "-ffp-contract=off" in info["flags"]
    if X86 and not info["scalar_only"]:  # a vector build (the default; the switch is off here)
        assert info["simd_built"] == ["scalar", "avx2", "avx512"] and "-mavx2" in info["isa_flags"]
        if {"avx2", "fma", "bmi2", "f16c"} <= cpu_flags():
            assert "avx2" in info["simd_usable"]
            if not os.environ.get("GBVIEWER_SIMD"):
                assert info["simd_selected"] == info["simd_usable"][-1] != "scalar"


def test_gbviewer_info_prints_the_build(capsys):
    assert main(["info"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 2 and lines[0] == simd_line(gb.build_info())
    assert lines[0].startswith(f"SIMD {_native.simd()} (built: scalar") and gb.build_info()["compiler"] in lines[1]
    assert main(["info", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["simd_usable"] == _native.simd_paths()
    assert main(["info", str(gb.DEFAULT_SCENE), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["build"]["simd_selected"] == _native.simd()


def configure(build: Path, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """`cmake -S ROOT -B build` for the CPU module alone (no CUDA), with this Python and its nanobind."""
    nb_dir = subprocess.check_output([sys.executable, "-m", "nanobind", "--cmake_dir"], text=True).strip()
    gen = ["-G", "Ninja"] if shutil.which("ninja") else []
    cmd = ["cmake", "-S", str(ROOT), "-B", str(build), *gen, "-DGBVIEWER_CUDA=OFF", f"-Dnanobind_DIR={nb_dir}",
           f"-DPython_EXECUTABLE={sys.executable}", "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON", *args]
    return subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300)


def hidden_highway() -> list[str]:
    """CMake arguments under which Highway's headers are not found: their include directory ignored."""
    dirs = [d for d in ("/usr/include", "/usr/local/include") if (Path(d) / "hwy/highway.h").exists()]
    return [f"-DCMAKE_IGNORE_PATH={';'.join(dirs)}"] if dirs else []


needs_cmake = pytest.mark.skipif(shutil.which("cmake") is None, reason="cmake is not installed")
x86_only = pytest.mark.skipif(not X86, reason="the Highway check's message is x86-64's (aarch64 has its own line)")


@pytest.mark.slow
@needs_cmake
@x86_only
def test_configure_without_highway_fails_with_one_line(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "GBVIEWER_SCALAR_ONLY"}
    proc = configure(tmp_path / "b", *hidden_highway(), env=env)
    assert proc.returncode != 0
    lines = [ln for ln in (proc.stdout + proc.stderr).splitlines() if ln.startswith(NO_HWY_LINE)]
    assert len(lines) == 1, proc.stdout + proc.stderr
    assert "apt-get install libhwy-dev" in lines[0] and "-DGBVIEWER_SCALAR_ONLY=ON" in lines[0]
    assert "GBVIEWER_SCALAR_ONLY=1 pip install ." in lines[0]


@pytest.fixture(scope="module")
def scalar_build(tmp_path_factory) -> Path:
    """A scalar-only configure (the environment switch, as pip passes it) with Highway hidden."""
    build = tmp_path_factory.mktemp("scalar") / "b"
    proc = configure(build, *hidden_highway(), env=dict(os.environ, GBVIEWER_SCALAR_ONLY="1"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert NO_HWY_LINE not in proc.stdout + proc.stderr
    return build


@pytest.mark.slow
@needs_cmake
def test_scalar_only_switch_configures_without_vector_paths(scalar_build):
    commands = json.loads((scalar_build / "compile_commands.json").read_text())
    files = {Path(c["file"]).name: c["command"] for c in commands}
    assert "blend_isa.cpp" not in files and "preprocess_isa.cpp" not in files
    assert "-DGBV_SCALAR_ONLY" in files["bindings.cpp"] and "GBV_HAVE_AVX2" not in files["simd.cpp"]


@pytest.mark.slow
@needs_cmake
def test_scalar_only_build_reports_it(scalar_build):
    subprocess.run(["cmake", "--build", str(scalar_build), "-j2"], check=True, capture_output=True, timeout=600)
    code = "import json, _native; print(json.dumps(_native.build_info()))"
    out = subprocess.run([sys.executable, "-c", code], cwd=scalar_build, capture_output=True, text=True,
                         check=True, timeout=60, env={k: v for k, v in os.environ.items() if k != "GBVIEWER_SIMD"})
    info = json.loads(out.stdout)
    assert info["scalar_only"] is True and info["simd_built"] == info["simd_usable"] == ["scalar"]
    assert "scalar-only build" in simd_line({"cpu_module": True, **info})
