"""A Scene's arrays are read-only: the renderers reuse what they derived from them per camera (the shared stage),
so an edit in place would draw a stale frame. A write fails with a message saying what to do; `editable()` gives
the copies an edited Scene is made of."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from helpers import front_camera, random_scene

import gbviewer as gb
from gbviewer.io.write import write_inria_ply
from gbviewer.model.scene import OitData

WRITES = {
    "in-place operator on a slice": lambda s: s.sh.__getitem__(slice(None)).__imul__(-1),
    "item assignment": lambda s: s.opacities.__setitem__(0, 0.5),
    "in-place operator": lambda s: s.means.__iadd__(1),
    "ufunc out": lambda s: np.multiply(s.scales, 2, out=s.scales),
    "a view's item": lambda s: s.sh[:, 0].__setitem__(0, 3.0),
}


@pytest.mark.parametrize("how", sorted(WRITES))
def test_a_write_into_a_rendered_scene_fails_saying_what_to_do(tmp_path, how):
    scene = gb.load(write_inria_ply(random_scene(200, seed=1, sh_degree=1), tmp_path / "s.ply"))
    cam = front_camera()
    first = gb.render(scene, cam)
    before = {name: np.array(a) for name, a in scene.arrays.items()}
    with pytest.raises(ValueError, match=r"read-only.*scene\.editable\(\)"):
        WRITES[how](scene)
    assert all(np.array_equal(before[name], a) for name, a in scene.arrays.items())
    assert np.array_equal(gb.render(scene, cam).rgb, first.rgb)


def test_an_edited_copy_renders_the_edit():
    """The issue's sequence, done the documented way: render, negate the SH, render again: the second frame is the
    edited scene's (as a fresh renderer draws it), not the first."""
    scene = random_scene(300, seed=2, sh_degree=1)
    cam = front_camera()
    first = gb.render(scene, cam)
    arrays = scene.editable()
    assert all(a.flags.writeable for a in arrays.values())
    arrays["sh"] *= -1
    edited = dataclasses.replace(scene, **arrays)
    again = gb.render(edited, cam)
    assert not np.array_equal(again.rgb, first.rgb)
    fresh = gb.Scene.from_arrays(
        np.array(scene.means),
        np.array(scene.scales),
        np.array(scene.quats),
        np.array(scene.opacities),
        -np.array(scene.sh),
    )
    assert np.array_equal(again.rgb, gb.render(fresh, cam).rgb)
    assert np.array_equal(gb.render(scene, cam).rgb, first.rgb)  # the original, unchanged


def test_arrays_handed_to_a_scene_are_read_only_and_computations_on_them_plain():
    means = np.zeros((4, 3), np.float32)
    weights = np.ones((4, 1), np.float32)
    scene = gb.Scene(
        means,
        np.ones((4, 3), np.float32),
        np.tile(np.float32([1, 0, 0, 0]), (4, 1)),
        np.ones(4, np.float32),
        np.zeros((4, 1, 3), np.float32),
        oit=OitData(view_weight_sh=weights),
    )
    with pytest.raises(ValueError):
        means[0, 0] = 1.0  # not through the array it was given as either
    with pytest.raises(ValueError, match="read-only"):
        scene.oit.view_weight_sh[0] = 2.0
    for out in (scene.means * 2, scene.means[[0, 1]], scene.means.min(axis=0), np.ascontiguousarray(scene.sh)):
        assert type(out) is np.ndarray
    copy = scene.means[[0, 1]]
    copy[0] = 5.0  # a copy is the caller's
    assert scene.means[0, 0] == 0.0


def test_ufunc_at_into_a_scene_array_fails_saying_what_to_do():
    """numpy's ufunc.at writes in place whatever an array's read-only flag says: np.add.at(s.opacities, ...)
    edited a rendered scene, and the next render was the stale first frame."""
    scene = random_scene(50, seed=3)
    before = np.array(scene.opacities)
    with pytest.raises(ValueError, match=r"read-only.*scene\.editable\(\)"):
        np.add.at(scene.opacities, [0, 1], 0.25)
    assert np.array_equal(scene.opacities, before)


def test_the_arrays_a_scene_views_are_read_only_too(tmp_path):
    """A loaded PLY's opacities view a writable array: s.opacities.base.base[:] = 0 edited the scene without a
    flag changed. Every array a Scene's array views is read-only; memory no array owns (a bytearray handed in) is
    copied."""
    scene = gb.load(write_inria_ply(random_scene(200, seed=4), tmp_path / "s.ply"))
    for a in scene.arrays.values():
        while isinstance(a, np.ndarray):
            assert not a.flags.writeable
            a = a.base
    memory = bytearray(np.ones(4, np.float32).tobytes())
    handed = gb.Scene(
        np.zeros((4, 3), np.float32),
        np.ones((4, 3), np.float32),
        np.tile(np.float32([1, 0, 0, 0]), (4, 1)),
        np.frombuffer(memory, np.float32),
        np.zeros((4, 1, 3), np.float32),
    )
    memory[:4] = bytes(4)
    assert handed.opacities[0] == 1.0 and handed.intact


def reopen(a: np.ndarray) -> np.ndarray:
    """The array `a` views, made writable again (numpy allows it for the array that owns the memory)."""
    while a.base is not None:
        a = a.base
    a.flags.writeable = True
    return a


def test_an_array_made_writable_again_is_an_edit_every_cache_sees(tmp_path, monkeypatch):
    """s.sh.base.flags.writeable = True, then an edit through it: the renders reused the first frame's stage and
    the LOD cache stored the edited tree under the file's key. Such a scene is no longer `intact`: each render
    derives its stage, cut and hierarchy anew, and nothing is cached for it."""
    monkeypatch.setattr(gb.lod.cache, "default_folder", lambda: tmp_path / "cache")
    scene = gb.load(write_inria_ply(random_scene(300, seed=6, sh_degree=1), tmp_path / "s.ply"))
    cam = front_camera()
    first = [gb.render(scene, cam, m).rgb for m in ("scalar", "scalar+lod:4")]
    assert scene.intact and gb.lod.cache.cache_key(scene, "depth") is not None
    reopen(scene.sh)[:] *= -1
    reopen(scene.means)[:, 0] += 0.05
    assert not scene.intact and gb.lod.cache.cache_key(scene, "depth") is None
    fresh = gb.Scene(**scene.editable())
    for m, before in zip(("scalar", "scalar+lod:4"), first):
        again = gb.render(scene, cam, m).rgb
        assert not np.array_equal(again, before)
        assert np.array_equal(again, gb.render(fresh, cam, m).rgb)
    assert gb.lod.hierarchy_for(scene) is not gb.lod.hierarchy_for(scene)


def splats(n: int = 4, **change) -> dict[str, np.ndarray]:
    arrays = {
        "means": np.zeros((n, 3), np.float32),
        "scales": np.full((n, 3), 0.1, np.float32),
        "quats": np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
        "opacities": np.full(n, 0.5, np.float32),
        "sh": np.zeros((n, 1, 3), np.float32),
    }
    return {**arrays, **change}


@pytest.mark.parametrize(
    "change, says",
    [
        ({"opacities": np.ones(3, np.float32)}, "field 'opacities': shape \\(3,\\), expected \\(4,\\)"),
        ({"sh": np.zeros((4, 3), np.float32)}, "field 'sh': shape \\(4, 3\\), expected \\(4, K, 3\\)"),
        ({"sh": np.zeros((4, 5, 3), np.float32)}, "sh has 5 coefficients"),
        ({"filter_3d": np.zeros(5, np.float32)}, "field 'filter_3d'"),
    ],
)
def test_a_scene_of_arrays_that_disagree_is_one_line(change, says):
    """Scene(...) took arrays of different splat counts (or an SH count of no degree): the renders raised the
    native module's ValueError, or drew K=5 as some degree. Its shapes are checked as from_arrays checks them."""
    with pytest.raises(gb.GBViewerError, match=says):
        gb.Scene(**splats(**change))


def test_level_of_detail_of_a_scene_it_cannot_draw_is_one_line():
    """A Scene of no splats, or made directly of NaN values (from_arrays drops those): level of detail raised the
    native build's or upload's ValueError; a RenderError names the scene, and the plain render still draws."""
    cam = front_camera(16, 12)
    with pytest.raises(gb.RenderError, match="no splats to build a level-of-detail hierarchy"):
        gb.render(gb.Scene(**{k: v[:0] for k, v in splats().items()}), cam, "scalar+lod:2")
    nan = gb.Scene(**splats(means=np.full((4, 3), np.nan, np.float32)))
    with pytest.raises(gb.RenderError, match="level of detail: .*non-finite"):
        gb.render(nan, cam, "scalar+lod:2")
    assert np.isfinite(gb.render(nan, cam).rgb).all()


@pytest.mark.parametrize("how", ["pickle", "deepcopy"])
def test_an_unpickled_scene_is_read_only_and_keeps_its_content_only_when_intact(tmp_path, how):
    """numpy's pickles restore arrays writable: an unpickled (or deep-copied) Scene took writes, and lost its cache
    key. It is read-only again with its file's content; one pickled after an edit carries no content."""
    import copy
    import pickle

    again = (lambda s: pickle.loads(pickle.dumps(s))) if how == "pickle" else copy.deepcopy
    scene = gb.load(write_inria_ply(random_scene(100, seed=8), tmp_path / "s.ply"))
    twin = again(scene)
    assert twin.intact and twin.content == scene.content and twin.content is not None
    with pytest.raises(ValueError, match="read-only"):
        twin.opacities[0] = 0.0
    reopen(scene.sh)[:] *= -1
    assert again(scene).content is None
