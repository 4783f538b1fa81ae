"""The house style, enforced: ruff (lint and format, `[tool.ruff]` in pyproject.toml) on every Python file and
clang-format (`.clang-format`) on the C++, CUDA and GLSL sources. A file either would change fails here, naming it;
`ruff check --fix . && ruff format . && clang-format -i FILES` fixes it (docs/architecture.md#style). And every source
file reads in one sitting: at most MAX_LINES lines."""

from __future__ import annotations

import fnmatch
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent
NATIVE = ("*.h", "*.cpp", "*.cu")
GLSL = ("*.glsl", "*.comp")
MAX_LINES = 400
SOURCE_DIRS = ("gbviewer", "native", "shaders", "tests", "bench", "tools", "scripts")


def tool(name: str) -> str:
    path = BIN / name
    if not path.exists():
        pytest.fail(f"{path} missing: {name} is a test dependency (pip install -e '.[dev]')")
    return str(path)


def run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(args, cwd=REPO, capture_output=True, text=True, timeout=300)


def c_sources() -> list[Path]:
    files = [p for pat in NATIVE for p in (REPO / "native").rglob(pat)]
    files += [p for pat in GLSL for p in (REPO / "shaders").glob(pat)]
    files += [p for pat in NATIVE for p in (REPO / "tests").rglob(pat)]
    return sorted(files)


def test_ruff_lint():
    out = run(tool("ruff"), "check", "--no-cache", ".")
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]


def test_ruff_format():
    out = run(tool("ruff"), "format", "--no-cache", "--check", ".")
    assert out.returncode == 0, out.stdout[-4000:] + out.stderr[-2000:]


def test_clang_format():
    files = c_sources()
    assert len(files) > 50, files  # the sources were found
    # GLSL is formatted as C++ (clang-format has no GLSL mode); the shaders share the headers' style
    bad = [
        str(f.relative_to(REPO))
        for f in files
        if run(tool("clang-format"), "--dry-run", "-Werror", f"--assume-filename={f.stem}.cpp", str(f)).returncode
    ]
    assert not bad, f"clang-format would change: {', '.join(bad)}"


@pytest.mark.parametrize("text,check", [("x = [1,2]\n", "format"), ("import os\n", "lint")])
def test_the_check_catches_violations(tmp_path, text, check):
    (tmp_path / "pyproject.toml").write_text((REPO / "pyproject.toml").read_text())
    (tmp_path / "bad.py").write_text(text)
    args = ["format", "--check"] if check == "format" else ["check"]
    out = subprocess.run([tool("ruff"), *args, "--no-cache", "bad.py"], cwd=tmp_path, capture_output=True, text=True)
    assert out.returncode != 0, out.stdout


def test_clang_format_catches_a_violation(tmp_path):
    (tmp_path / ".clang-format").write_text((REPO / ".clang-format").read_text())
    bad = tmp_path / "bad.cpp"
    bad.write_text("int f( int a ){return a;}\n")
    out = subprocess.run([tool("clang-format"), "--dry-run", "-Werror", str(bad)], cwd=tmp_path, capture_output=True)
    assert out.returncode != 0


def test_every_source_file_reads_in_one_sitting():
    files = [p for d in SOURCE_DIRS for pat in ("*.py", *NATIVE, *GLSL, "*.sh") for p in (REPO / d).rglob(pat)]
    assert len(files) > 300, len(files)  # the sources were found
    long = {str(p.relative_to(REPO)): n for p in files if (n := len(p.read_text().splitlines())) > MAX_LINES}
    assert not long, f"over {MAX_LINES} lines: {long}"


def test_every_test_file_lies_where_pytest_looks():
    """pytest skips folders named like build or dist (its norecursedirs) without a word: none of ours may be."""
    skipped = ("*.egg", ".*", "_darcs", "build", "CVS", "dist", "node_modules", "venv", "{arch}")
    tests = REPO / "tests"
    hidden = [
        str(p.relative_to(REPO))
        for p in tests.rglob("test_*.py")
        if any(fnmatch.fnmatch(part, pat) for part in p.relative_to(tests).parts[:-1] for pat in skipped)
    ]
    assert not hidden, f"pytest would not collect: {hidden}"
