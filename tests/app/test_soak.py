"""A short run of the viewer soak (tools/soak_viewer.py; the long one is run by hand): scenes good and bad opened,
switched and superseded in the real window with renders, backend switches and videos in flight."""

from __future__ import annotations

import pytest
from soak_viewer import run_soak

pytestmark = [pytest.mark.display, pytest.mark.slow]


def test_short_soak_keeps_the_app_alive_and_its_gl_objects_bounded(xvfb):
    report = run_soak(cycles=20, sample_every=5, warmup=5, trace=False)
    assert report["alive"], report["crash"]
    assert report["problems"] == []
    assert report["bad_files_opened"] >= 6 and report["bad_file_messages"] == report["bad_files_opened"]
    s = report["summary"]
    # a leak grows with the cycles (15 after the warm-up); one object more at the end than after the warm-up is a
    # feature first used later in the run (seen in the full suite: 9 textures against 8), not a leak
    assert all(s["gl_last"][k] <= s["gl_after_warmup"][k] + 1 for k in s["gl_last"]), s
    assert s["rss_max_mib"] < s["rss_first_mib"] + 1024  # generous: RSS follows the open scene and the allocator
    # (report["ok"] is the long soak's stricter verdict: every GL count back at its warm-up value)
