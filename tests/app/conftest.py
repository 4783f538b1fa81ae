"""Fixtures of the viewer tests: an Xvfb server (Mesa llvmpipe) for the tests that open the real window."""

from __future__ import annotations

import shutil

import pytest

from helpers import skip_or_fail
from soak_viewer import xvfb_display


@pytest.fixture(scope="module")
def xvfb():
    """DISPLAY of an Xvfb server started for the module's tests."""
    if shutil.which("Xvfb") is None:
        skip_or_fail("Xvfb is not installed (apt-get install xvfb; scripts/setup.sh installs it)")
    with xvfb_display() as display:
        yield display
