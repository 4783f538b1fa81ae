"""The optional extras: with every extra's package blocked (as after a plain `pip install gbviewer`), the package and
its command line import, render and say in one line which extra a feature needs (exit status 2)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

import gbviewer as gb
from gbviewer.core.extras import EXTRAS, MissingExtra, require

REPO = Path(gb.__file__).resolve().parents[1]
BLOCKED = ("glfw", "imgui_bundle", "matplotlib", "skimage", "pycolmap", "imageio_ffmpeg", "ray", "torch")

# A child Python in which importing a blocked package (or any of its submodules) raises ImportError.
CHILD = textwrap.dedent("""
    import importlib.abc, json, pkgutil, sys
    BLOCKED = set(sys.argv[1].split(","))

    class Block(importlib.abc.MetaPathFinder):
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in BLOCKED:
                raise ImportError(f"No module named {name!r} (blocked)")

    sys.meta_path.insert(0, Block())
    import gbviewer as gb
    from gbviewer import cli

    core = [m.name for m in pkgutil.walk_packages(gb.__path__, "gbviewer.")
            if not m.name.startswith("gbviewer.app.") and m.name not in ("gbviewer.__main__",
                                                                         "gbviewer.io.datasets.colmap_child")]
    for name in core:
        __import__(name)
    scene = gb.load(gb.DEFAULT_SCENE)
    frame = gb.render(scene, gb.orbit_camera(scene, width=24, height=16), "gaussian_blending")
    status = {argv[0]: cli.main(argv) for argv in json.loads(sys.argv[2])}
    leaked = sorted(m for m in sys.modules if m.split(".")[0] in BLOCKED)
    print(json.dumps({"imported": len(core), "shape": list(frame.rgb.shape), "status": status, "leaked": leaked}))
""")


def run_blocked(tmp_path: Path, *argvs: list[str], env: dict | None = None) -> tuple[dict, list[str]]:
    """Run CHILD with BLOCKED blocked and the command lines `argvs`: its summary and its stderr lines."""
    proc = subprocess.run(
        [sys.executable, "-c", CHILD, ",".join(BLOCKED), json.dumps(list(argvs))],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(REPO), **(env or {})},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.splitlines()[-1]), proc.stderr.splitlines()


def test_core_imports_renders_and_runs_the_render_command_without_any_extra(tmp_path):
    out = tmp_path / "a.png"
    summary, err = run_blocked(
        tmp_path,
        ["render", str(gb.DEFAULT_SCENE), "--width", "32", "--height", "24", "--backend", "cpu", "--out", str(out)],
    )
    assert summary["imported"] > 50 and summary["shape"] == [16, 24, 3] and summary["leaked"] == []
    assert summary["status"] == {"render": 0} and out.stat().st_size > 0 and err == []


@pytest.mark.parametrize(
    "argv, extra, module",
    [
        (["view", "{scene}"], "viewer", "imgui_bundle"),
        (["video", "{scene}", "--frames", "2", "--out", "{tmp}/v.mp4"], "video", "imageio_ffmpeg"),
        (["demo", "--out", "{tmp}/demo"], "video", "imageio_ffmpeg"),
        (["bench", "{scene}", "--plots", "{tmp}/plots"], "eval", "matplotlib"),
        (["eval", "{scene}", "--data", "{tmp}"], "eval", "skimage"),
    ],
)
def test_a_feature_without_its_extra_says_which_to_install_in_one_line(tmp_path, argv, extra, module):
    argv = [a.format(scene=gb.DEFAULT_SCENE, tmp=tmp_path) for a in argv]
    summary, err = run_blocked(tmp_path, argv, env={"DISPLAY": ":0"})  # view: a display, so the window is asked for
    assert summary["status"] == {argv[0]: 2}
    assert len(err) == 1 and err[0].startswith("gbviewer: error: ") and f"needs {module} (" in err[0], err
    assert err[0].endswith(f"pip install 'gbviewer[{extra}]'")
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # refused before anything was written


def test_require_imports_checks_and_names_the_extra():
    assert require("eval", "matplotlib", "plots") is sys.modules["matplotlib"]
    assert require("eval", "matplotlib", "plots", load=False) is None
    with pytest.raises(ValueError, match="not a package of the extra 'video'"):
        require("video", "glfw", "x")
    for extra, modules in EXTRAS.items():
        assert modules and all(m.isidentifier() for m in modules), extra


def test_missing_extra_is_one_line_and_a_gbviewer_error():
    exc = MissingExtra("video", "imageio_ffmpeg", "an MP4 video", "No module named\n'imageio_ffmpeg'")
    assert isinstance(exc, gb.GBViewerError) and exc.extra == "video" and "\n" not in str(exc)
    assert str(exc) == (
        "an MP4 video needs imageio_ffmpeg (No module named 'imageio_ffmpeg'): pip install 'gbviewer[video]'"
    )


def test_pyproject_extras_hold_the_packages_require_names():
    import tomllib

    project = tomllib.loads((Path(__file__).resolve().parents[2] / "pyproject.toml").read_text())["project"]
    pip_name = {
        "glfw": "glfw",
        "imgui_bundle": "imgui-bundle",
        "skimage": "scikit-image",
        "matplotlib": "matplotlib",
        "pycolmap": "pycolmap",
        "imageio_ffmpeg": "imageio-ffmpeg",
        "ray": "ray",
        "torch": "torch",
    }
    core = " ".join(project["dependencies"])
    for extra, modules in EXTRAS.items():
        listed = " ".join(project["optional-dependencies"][extra])
        for m in modules:
            assert pip_name[m] in listed and pip_name[m] not in core, (extra, m)
