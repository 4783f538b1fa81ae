"""What the environment can set around gbviewer: every value either works or is one line, never a crash."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np

RENDER = (
    "import sys, numpy as np, gbviewer as gb; s = gb.load(gb.DEFAULT_SCENE); cam = gb.orbit_camera(s, width=48, "
    "height=32); modes = [m.label for m in gb.Mode] + ['scalar+lod:3']; "
    "np.save(sys.argv[1], np.stack([gb.render(s, cam, m).rgb for m in modes] + "
    "[np.broadcast_to(gb.trace_pixel(s, cam, 20, 16, m).color, (32, 48, 3)) for m in modes]))"
)


def test_a_huge_omp_num_threads_renders_as_a_capped_team(tmp_path):
    """OMP_NUM_THREADS=100000 made the first parallel region crash in libgomp (SIGSEGV; 50000 made it exit 1), a
    pixel trace's too: the native teams are capped at the library's MAX_THREADS, and every mode's frame and trace
    are those of a small team."""
    images = {}
    for n in ("100000", "2"):
        out = tmp_path / f"{n}.npy"
        env = {**os.environ, "OMP_NUM_THREADS": n, "XDG_CACHE_HOME": str(tmp_path / "cache")}
        run = subprocess.run(
            [sys.executable, "-c", RENDER, str(out)], env=env, capture_output=True, text=True, cwd=tmp_path, timeout=300
        )  # not the checkout, whose gbviewer/ has no module built
        assert run.returncode == 0, (n, run.returncode, run.stderr[-2000:])
        images[n] = np.load(out)
    assert np.array_equal(images["100000"], images["2"])
