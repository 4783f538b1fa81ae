"""eval's caches hold what their inputs are now: ground-truth levels keyed by the photo's bytes and read as
untrusted input, scenes reloaded once their file is replaced."""

from __future__ import annotations

import io
import os
import shutil

import numpy as np
from dataset_builders import shots, write_blender
from helpers import random_scene
from PIL import Image

import gbviewer as gb
from gbviewer import eval as ev
from gbviewer.eval import multiscale as gt_module
from gbviewer.io.datasets import load_dataset, read_photo
from gbviewer.io.write import write_inria_ply
from gbviewer.outputs.metrics import composite, premultiplied_box_downsample
from gbviewer.render import RenderSettings

WHITE = (1.0, 1.0, 1.0)


def test_a_cached_level_is_the_photo_s_content_and_an_entry_untrusted(tmp_path, bundled_scene):
    """The ground-truth cache keyed a photo by path, size and modification time: a same-size edit with the time
    restored (cp -p, rsync -a, tar) scored against the old photo. It is keyed by the photo's bytes; an entry of
    NaN, of values beyond [0, 1], with a header claiming a huge shape, or a FIFO in its place is recomputed."""
    data = write_blender(tmp_path / "data", shots(bundled_scene, n=1, vary=False), test=(0,))
    view, cache = load_dataset(data).views[0], tmp_path / "cache"
    photo = np.array(Image.open(view.image))
    Image.fromarray(photo).save(view.image, compress_level=0)  # stored: its size is its pixel count's
    first = ev.ground_truths(view, [1 / 2], WHITE, cache)[0]
    st = view.image.stat()
    photo[..., :3] = 255 - photo[..., :3]
    Image.fromarray(photo).save(view.image, compress_level=0)
    os.utime(view.image, ns=(st.st_atime_ns, st.st_mtime_ns))
    assert view.image.stat().st_size == st.st_size
    expected = composite(premultiplied_box_downsample(read_photo(view.image), 2), WHITE)
    edited = ev.ground_truths(view, [1 / 2], WHITE, cache)[0]
    assert np.array_equal(edited, expected) and not np.array_equal(edited, first)
    entry = gt_module._entry(cache, gt_module.photo_digest(view.image), 2)
    good = np.load(entry)
    for bad in (np.full_like(good, np.nan), good + 2):
        np.save(entry, bad)
        assert np.array_equal(ev.ground_truths(view, [1 / 2], WHITE, cache)[0], expected)
    huge = io.BytesIO()
    np.lib.format.write_array_header_1_0(huge, {"descr": "<f4", "fortran_order": False, "shape": (10**6, 10**6, 4)})
    entry.write_bytes(huge.getvalue())
    assert np.array_equal(ev.ground_truths(view, [1 / 2], WHITE, cache)[0], expected)
    entry.unlink()
    os.mkfifo(entry)
    assert gt_module._cached(entry, good.shape[:2]) is None


def test_a_replaced_scene_file_is_evaluated_anew_in_the_same_process(tmp_path, bundled_scene):
    """Workers kept scenes by path: a second run_eval in the same process (or on a Ray worker that lives on) after
    the scene file was replaced scored the old scene."""
    data = write_blender(tmp_path / "data", shots(bundled_scene, n=1, vary=False), test=(0,))
    scene = tmp_path / "s.ply"
    shutil.copy(gb.DEFAULT_SCENE, scene)

    def scores() -> list[float]:
        r = ev.run_eval(
            [(scene, data)], RenderSettings.parse_list("scalar"), [1.0], backend="cpu", cache=tmp_path / "c"
        )
        return [x["psnr"] for s in r.scenes for v in s.results for x in v.results]

    first = scores()
    scene.unlink()
    write_inria_ply(random_scene(300, seed=3), scene)
    assert scores() != first
