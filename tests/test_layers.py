"""The one-way layers (docs/architecture.md#layers), checked by import-linter on the source tree: a lower layer
importing a higher one, two modules importing each other, one CLI subcommand module importing another, or a module
outside the viewer importing an optional extra's package other than through gbviewer.core.extras, fails here (and the
check is shown to catch each)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
LINT = Path(sys.executable).with_name("lint-imports")


def lint(root: Path) -> subprocess.CompletedProcess:
    """lint-imports with the contracts of pyproject.toml, on the gbviewer package found under `root`."""
    if not LINT.exists():
        pytest.fail(f"{LINT} missing: import-linter is a test dependency (pip install -e '.[dev]')")
    return subprocess.run(
        [str(LINT), "--no-cache", str(REPO / "pyproject.toml")],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=300,
        env={"PYTHONPATH": str(root), "PATH": "/usr/bin:/bin"},
    )


def test_layers_and_no_cycles():
    out = lint(REPO)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]
    assert "Contracts: 4 kept, 0 broken." in out.stdout


@pytest.mark.parametrize(
    "module,line,contract",
    [
        ("model/camera.py", "from ..render import Mode\n", "layers"),  # io|model|lod must not import render
        ("render/types.py", "from ..app import state\n", "layers"),
        ("outputs/metrics.py", "from . import figure\n", "cycles"),  # figure imports metrics: a cycle inside one layer
        ("app/state.py", "from . import window\n", "cycles"),  # window composes state
        ("app/ui/keys.py", "from .. import state\n", "cycles"),  # state uses ui/: a cycle between app's packages
        ("newmodule.py", "X = 1\n", "layers"),  # exhaustive: a new top-level module must be given a layer
        ("outputs/metrics.py", "def plot():\n    import matplotlib\n", "extras"),  # even lazily: through extras.require
        ("render/cpu.py", "import glfw\n", "extras"),
        ("cli/video.py", "from .render import cmd_render\n", "cli"),  # subcommands share only cli.options
    ],
)
def test_the_check_catches_violations(tmp_path, module, line, contract):
    shutil.copytree(REPO / "gbviewer", tmp_path / "gbviewer", ignore=shutil.ignore_patterns("*.so", "__pycache__"))
    target = tmp_path / "gbviewer" / module
    target.write_text((target.read_text() if target.exists() else "") + line)
    out = lint(tmp_path)
    assert out.returncode != 0, out.stdout[-2000:]
    name = {
        "layers": "One-way layers BROKEN",
        "cycles": "No import cycles between sibling modules BROKEN",
        "extras": "Optional extras only through gbviewer.core.extras BROKEN",
        "cli": "Independent subcommands (gbviewer.cli) BROKEN",
    }
    assert name[contract] in out.stdout
