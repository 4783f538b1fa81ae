"""Fixtures of the viewer tests: an Xvfb server (Mesa llvmpipe) for the tests that open the real window, and a small
synthetic training dataset for the photo pane."""

from __future__ import annotations

import shutil
import threading

import pytest
from dataset_builders import shots, write_colmap
from helpers import skip_or_fail
from soak_viewer import xvfb_display


@pytest.fixture(autouse=True)
def _builds_end_with_their_test():
    """A hierarchy build the viewer started (`loading.start_lod`) ends within its test: one still running would write
    its tree into the cache folder of the next test (the folder is read from XDG_CACHE_HOME when it looks)."""
    yield
    for t in threading.enumerate():
        if t.name == "gbviewer-lod":
            t.join(120)
            assert not t.is_alive(), "a hierarchy build of this test ran on for 120 s after it"


@pytest.fixture(scope="module")
def xvfb():
    """DISPLAY of an Xvfb server started for the module's tests."""
    if shutil.which("Xvfb") is None:
        skip_or_fail("Xvfb is not installed (apt-get install xvfb; scripts/setup.sh installs it)")
    with xvfb_display() as display:
        yield display


@pytest.fixture(scope="session")
def capture(bundled_scene, tmp_path_factory):
    """A COLMAP capture of the bundled scene (tests/dataset_builders.py): 9 photos of 130x100, v00 and v08 test."""
    pytest.importorskip("pycolmap")
    return write_colmap(tmp_path_factory.mktemp("capture"), shots(bundled_scene))


@pytest.fixture
def app(xvfb, tmp_path, monkeypatch):
    """The viewer window (1040x700) on the bundled scene, with its settings in tmp_path; closed after the test."""
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    from gbviewer.app.window import ViewerApp

    a = ViewerApp(None, size=(1040, 700))
    a.state.settings.show_info = False  # comparisons need the image without the stats lines; one test turns it on
    yield a
    a.close()
