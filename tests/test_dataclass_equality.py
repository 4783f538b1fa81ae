"""Dataclass equality over arrays: Python 3.13 compares a dataclass's fields one by one (`a.R == b.R and ...`), which
raises for numpy arrays; before 3.13 it compared tuples, which raised only for distinct arrays. Every dataclass of the
package either compares its arrays by value (Camera) or by identity (eq=False)."""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import pkgutil

import numpy as np

import gbviewer as gb
from gbviewer.model.keyframes import Keyframe

# field types whose == is elementwise or undefined: a dataclass holding one needs its own __eq__ or eq=False
_ARRAYISH = ("ndarray", "np.", "Scene", "Frame", "Hierarchy", "Cut", "FrameStats", "Any", "object")


def _package_dataclasses() -> list[type]:
    found = []
    for info in pkgutil.walk_packages(gb.__path__, "gbviewer."):
        if info.name.endswith("__main__"):
            continue
        module = importlib.import_module(info.name)
        found += [
            obj
            for obj in vars(module).values()
            if inspect.isclass(obj) and dataclasses.is_dataclass(obj) and obj.__module__ == module.__name__
        ]
    return found


def test_no_dataclass_compares_arrays_field_by_field():
    offenders = []
    classes = _package_dataclasses()
    assert gb.Camera in classes and len(classes) > 20
    for cls in classes:
        own_eq = "__eq__" in cls.__dict__ and cls.__dict__["__eq__"].__qualname__.startswith(cls.__qualname__ + ".")
        if not cls.__dataclass_params__.eq or own_eq:
            continue
        bad = [f.name for f in dataclasses.fields(cls) if any(word in str(f.type) for word in _ARRAYISH)]
        if bad:
            offenders.append(f"{cls.__module__}.{cls.__qualname__}: {bad}")
    assert not offenders, offenders


def test_cameras_compare_and_hash_by_value(bundled_scene):
    a = gb.orbit_camera(bundled_scene, 30, 20, width=64, height=48)
    b = dataclasses.replace(a, R=a.R.copy(), t=a.t.copy())  # equal values, distinct arrays
    assert a == b and hash(a) == hash(b) and len({a, b}) == 1
    moved = dataclasses.replace(a, t=a.t + np.float32(1e-3))
    assert a != moved and dataclasses.replace(a, name="other") != a and a != "camera"
    keyframe = Keyframe(a, 1.0, None)  # a dataclass holding a camera compares through Camera.__eq__
    assert keyframe == dataclasses.replace(keyframe, camera=b)
