"""The render API: renderer reuse without keeping scenes alive."""

from __future__ import annotations

import gc
import weakref

import numpy as np

import gbviewer as gb
from conftest import front_camera, random_scene


def test_get_renderer_reuses_and_releases_scenes():
    cam = front_camera()
    first = random_scene(50, seed=0)
    a = gb.render(first, cam, "scalar").rgb
    assert gb.get_renderer(first, "cpu") is gb.get_renderer(first, "cpu")  # no second upload
    gone = weakref.ref(first)
    second = random_scene(50, seed=1)
    b = gb.render(second, cam, "scalar").rgb
    del first
    gc.collect()
    assert gone() is None  # the cache holds the last scene only
    assert not np.array_equal(a, b)
    np.testing.assert_array_equal(gb.render(second, cam, "scalar").rgb, b)
