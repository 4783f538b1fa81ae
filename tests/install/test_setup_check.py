"""scripts/setup.sh without root: scripts/check_system.sh, run as an unprivileged user, names the Debian
package of each missing piece on one line, stops only for what the build needs, and lets GBVIEWER_SCALAR_ONLY=1
go on without Highway; setup.sh stops before creating its venv when the build cannot succeed. Nothing is
installed: the checks only read, and missing tools are simulated with a PATH that lacks them. The unprivileged user
runs copies of the scripts in a folder it can read, wherever this checkout lies (a clone under /root is private)."""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BASH = shutil.which("bash") or "/bin/bash"
SETPRIV = shutil.which("setpriv")
# The system's Python (the one a setup starts from; a pyenv or venv under /root is out of the unprivileged user's reach)
SYS_PY = shutil.which("python3", path="/usr/local/bin:/usr/bin:/bin")


def as_nobody(cmd: list[str], env: dict[str, str]) -> subprocess.CompletedProcess:
    """Run cmd as uid/gid 65534 (nobody) when we are root, else as ourselves (already unprivileged)."""
    root = os.geteuid() == 0
    if root and SETPRIV is None:
        pytest.skip("running as root without setpriv (util-linux) to drop to an unprivileged user")
    if SYS_PY is None:
        pytest.skip("no system python3 in /usr/local/bin, /usr/bin or /bin")
    drop = [SETPRIV, "--reuid=65534", "--regid=65534", "--clear-groups"] if root else []
    return subprocess.run([*drop, *cmd], capture_output=True, text=True, env=env, timeout=60)


def readable_dir(tmp_path_factory, name: str) -> Path:
    """An empty folder the unprivileged user can read and enter."""
    d = tmp_path_factory.mktemp(name)
    for p in (d, *list(d.parents)[:-1]):  # pytest's base folder is private to us: open the way down to d
        if p.stat().st_uid == os.geteuid():
            p.chmod(p.stat().st_mode | 0o055)
    return d


@pytest.fixture
def bin_dir(tmp_path_factory) -> Path:
    """An empty folder the unprivileged user can read, for a PATH of chosen tools."""
    return readable_dir(tmp_path_factory, "bin")


@pytest.fixture
def work(tmp_path_factory) -> Path:
    """A copy of the checkout's scripts/ and pyproject.toml in a folder the unprivileged user can read."""
    work = readable_dir(tmp_path_factory, "checkout")
    shutil.copytree(ROOT / "scripts", work / "scripts")
    shutil.copy(ROOT / "pyproject.toml", work)
    for p in work.rglob("*"):
        p.chmod(p.stat().st_mode | 0o055)
    return work


@pytest.fixture
def check(work) -> Path:
    return work / "scripts" / "check_system.sh"


def lines(proc: subprocess.CompletedProcess) -> list[str]:
    return (proc.stdout + proc.stderr).splitlines()


def test_every_line_names_a_package_and_the_status_follows_them(check):
    proc = as_nobody([BASH, str(check)], {"PATH": os.environ["PATH"], "PYTHON": SYS_PY})
    out = lines(proc)
    assert all(ln.startswith("setup: ") and "apt-get install " in ln for ln in out), out
    assert proc.returncode == (1 if any(ln.endswith("(the build needs it)") for ln in out) else 0), out


def test_missing_tools_are_named_with_their_packages(bin_dir, check):
    (bin_dir / "python3").symlink_to(SYS_PY)
    proc = as_nobody([BASH, str(check)], {"PATH": str(bin_dir)})
    out = lines(proc)
    assert proc.returncode == 1
    for tool, pkg in [
        ("a C++ compiler (c++)", "build-essential"),
        ("cmake", "cmake"),
        ("Xvfb", "xvfb xauth"),
        ("glslangValidator", "glslang-tools"),
        ("qemu-x86_64", "qemu-user"),
        ("aarch64-linux-gnu-g++", "crossbuild-essential-arm64"),
        ("qemu-aarch64", "qemu-user"),
        ("clang++", "clang libomp-dev"),
        ("debootstrap", "debootstrap"),
    ]:
        assert sum(ln.startswith(f"setup: missing {tool}: apt-get install {pkg} (") for ln in out) == 1, (tool, out)
    assert not any("Highway" in ln for ln in out)  # no compiler: the headers are looked for in /usr/include


def fake_compiler(bin_dir: Path) -> dict[str, str]:
    """A PATH whose c++ finds no header (so Highway counts as missing), everything else as installed."""
    (bin_dir / "c++").write_text("#!/bin/sh\nexit 1\n")
    (bin_dir / "c++").chmod(0o755)
    return {"PATH": f"{bin_dir}:{os.environ['PATH']}", "PYTHON": SYS_PY}


def test_missing_highway_is_downloaded_unless_the_download_is_off(bin_dir, check):
    env = fake_compiler(bin_dir)
    proc = as_nobody([BASH, str(check)], env)
    out = lines(proc)
    hwy = [ln for ln in out if "Highway" in ln]
    assert len(hwy) == 1 and hwy[0].startswith("setup: note: ") and "the build downloads the pinned" in hwy[0], out
    assert proc.returncode == (1 if any(ln.endswith("(the build needs it)") for ln in out) else 0), out
    out = lines(as_nobody([BASH, str(check)], {**env, "GBVIEWER_FETCH_HIGHWAY": "OFF"}))
    hwy = [ln for ln in out if "Highway" in ln]
    assert hwy == [
        "setup: missing Google Highway's headers (hwy/highway.h; the CPU module's vector paths; "
        "GBVIEWER_FETCH_HIGHWAY is off): apt-get install libhwy-dev, or set GBVIEWER_SCALAR_ONLY=1 for a "
        "slower scalar-only build (the build needs it)"
    ], out
    proc = as_nobody([BASH, str(check)], {**env, "GBVIEWER_SCALAR_ONLY": "1"})
    out = lines(proc)
    hwy = [ln for ln in out if "Highway" in ln]
    assert len(hwy) == 1 and hwy[0].startswith("setup: WARNING: ") and "scalar-only" in hwy[0], out
    assert proc.returncode == (1 if any(ln.endswith("(the build needs it)") for ln in out) else 0), out


def test_setup_without_root_stops_before_the_venv(bin_dir, work):
    work.chmod(0o777)  # so that a setup which went on could write (it must not get there)
    (bin_dir / "python3").symlink_to(SYS_PY)
    for tool in ("id", "dirname"):  # what setup.sh itself runs; no cmake, no compiler
        (bin_dir / tool).symlink_to(shutil.which(tool))
    proc = as_nobody([BASH, str(work / "scripts" / "setup.sh")], {"PATH": str(bin_dir)})
    out = lines(proc)
    assert proc.returncode == 1 and not (work / ".venv").exists(), out
    assert out[0] == "setup: not root or no apt-get: installing no system packages, checking what is there"
    assert "setup: missing cmake: apt-get install cmake (the build needs it)" in out
    assert out[-1].startswith("setup: stopped: install what is missing above"), out


def test_test_tools_are_checked_only_for_the_tests(bin_dir, check):
    (bin_dir / "python3").symlink_to(SYS_PY)
    out = lines(as_nobody([BASH, str(check)], {"PATH": str(bin_dir), "GBVIEWER_SETUP_DEV": "0"}))
    assert any("missing cmake" in ln for ln in out), out
    assert not any(tool in ln for ln in out for tool in ("Xvfb", "qemu", "clang++", "debootstrap")), out


@pytest.mark.parametrize("args, installs", [([], [".[viewer,video]"]), (["--dev"], [".[dev,ray]"])])
def test_the_viewer_setup_installs_no_torch_and_no_ray(work, args, installs):
    """The first command installs the viewer's and the main job's packages only; --dev adds the tests' (torch only
    where scripts/pick_torch.py finds a CPU build: the fake Python here finds none). pip is a logging stand-in."""
    venv_bin = work / ".venv" / "bin"
    venv_bin.mkdir(parents=True)
    log = work / "pip-calls.log"
    (venv_bin / "python").write_text(
        f'#!/bin/sh\necho "$*" >> {log}\ncase "$1" in scripts/pick_torch.py) exit 1;; esac\nexit 0\n'
    )
    for p in (work, work / ".venv", venv_bin, venv_bin / "python"):
        p.chmod(0o777)
    proc = as_nobody([BASH, str(work / "scripts" / "setup.sh"), *args], {"PATH": os.environ["PATH"], "PYTHON": SYS_PY})
    assert proc.returncode == 0 and log.exists(), lines(proc)
    calls = log.read_text().splitlines()
    pip = [c.split()[-1] for c in calls if c.startswith("-m pip install") and "--upgrade pip" not in c]
    assert pip == installs, calls
    assert ("scripts/pick_torch.py" in calls) == bool(args) and not any("torch" in c or "duplex" in c for c in pip)


def test_an_unknown_setup_option_is_one_line(work):
    proc = subprocess.run([BASH, str(work / "scripts" / "setup.sh"), "--tests"], capture_output=True, text=True)
    assert proc.returncode == 2 and lines(proc) == [
        "setup: unknown option --tests: expected nothing (the viewer) or --dev (the tests too)"
    ]
