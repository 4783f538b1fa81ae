"""`gb.load(path, progress=fn, cancel=event)` for every format: monotonic reports per unit that end at their total,
a bounded number of them, the same scene as a load without them, and cancellation that leaves nothing behind."""

from __future__ import annotations

import gc
import os
import threading

import numpy as np
import plyfile
import pytest
from encoders import encode_compressed_ply, encode_splat, encode_spz, random_params, sog_files, write_sog

import gbviewer as gb
from gbviewer.io import progress as load_progress

N = 3000


def _inria(path, s, text=False):
    scene = gb.Scene.from_arrays(s["means"], s["scales"], s["quats"], s["opacities"], s["sh"])
    gb.io.write_inria_ply(scene, path)
    if text:  # the same rows as an ASCII PLY, which plyfile reads line by line
        ply = plyfile.PlyData.read(str(path))
        path.unlink()
        plyfile.PlyData([ply["vertex"]], text=True).write(str(path))
    return path


def _write(kind: str, folder):
    s = random_params(N, sh_degree=2, seed=7)
    s0 = random_params(N, seed=8)
    path = folder / kind
    if kind in ("inria", "ascii"):
        return _inria(path, s, text=kind == "ascii")
    data = {
        "compressed": lambda: encode_compressed_ply(s),
        "spz-gzip": lambda: encode_spz(s, 2),
        "spz-raw": lambda: encode_spz(s, 3, gzipped=False),
        "spz-zstd": lambda: encode_spz(s, 4),
        "splat": lambda: encode_splat(s0),
    }.get(kind)
    if data is not None:
        path.write_bytes(data())
        return path
    return write_sog(sog_files(s0), path, bundled=kind == "sog-zip")


KINDS = ["inria", "ascii", "compressed", "spz-gzip", "spz-raw", "spz-zstd", "splat", "sog-zip", "sog-folder"]
SPLATS_REPORTED = {"ascii", "compressed", "spz-gzip", "spz-raw", "spz-zstd", "splat"}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("progress")
    return {kind: _write(kind, folder) for kind in KINDS}


@pytest.fixture()
def small_chunks(monkeypatch):
    """Chunks of one byte / one splat at least: every phase is REPORTS chunks, the most it may have."""
    monkeypatch.setattr(load_progress, "MIN_BYTES", 1)
    monkeypatch.setattr(load_progress, "MIN_SPLATS", 1)


def check_reports(calls: list[tuple[int, int, str]]) -> dict[str, int]:
    """Per unit: one total, done from 0 up to it, never back; bytes before splats. Returns the calls per unit."""
    units = list(dict.fromkeys(unit for _, _, unit in calls))
    assert units in (["bytes"], ["bytes", "splats"]), units
    per_unit = {}
    for unit in units:
        seq = [(d, t) for d, t, u in calls if u == unit]
        assert len({t for _, t in seq}) == 1 and seq[0][0] == 0 and seq[-1][0] == seq[-1][1] > 0, (unit, seq)
        assert all(a[0] <= b[0] for a, b in zip(seq, seq[1:])), (unit, seq)
        per_unit[unit] = len(seq)
    assert [u for _, _, u in calls] == sorted((u for _, _, u in calls), key=units.index)  # one phase after the other
    return per_unit


def same_scene(a: gb.Scene, b: gb.Scene) -> None:
    for name in ("means", "scales", "quats", "opacities", "sh"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


@pytest.mark.parametrize("kind", KINDS)
def test_progress_is_monotonic_bounded_and_ends_at_the_total(files, kind, small_chunks):
    plain = gb.load(files[kind])
    calls: list[tuple[int, int, str]] = []
    scene = gb.load(files[kind], progress=lambda *c: calls.append(c))
    per_unit = check_reports(calls)
    assert all(n <= load_progress.REPORTS + 2 for n in per_unit.values()), per_unit
    assert ("splats" in per_unit) == (kind in SPLATS_REPORTED)
    if "splats" in per_unit:
        assert calls[-1] == (N, N, "splats") and per_unit["splats"] > load_progress.REPORTS // 2
    total_bytes = next(t for _, t, u in calls if u == "bytes")
    if not kind.startswith("sog"):  # a SOG's bytes are those of its images
        assert total_bytes == files[kind].stat().st_size
    assert per_unit["bytes"] > (4 if kind.startswith("sog") else load_progress.REPORTS // 2)  # chunk by chunk
    same_scene(scene, plain)  # decoded in 100 chunks: the same arrays as in one


@pytest.mark.parametrize("kind", KINDS)
def test_default_chunks_report_a_few_times(files, kind):
    calls: list[tuple[int, int, str]] = []
    gb.load(files[kind], progress=lambda *c: calls.append(c))
    per_unit = check_reports(calls)
    assert all(2 <= n <= 12 for n in per_unit.values()), per_unit  # small files: a chunk or a few


def _open_fds() -> set[str]:
    return set(os.listdir("/proc/self/fd")) if os.path.isdir("/proc/self/fd") else set()


@pytest.mark.parametrize("kind", KINDS)
def test_cancel_at_the_first_report_leaves_nothing_behind(files, kind, small_chunks):
    fds, threads = _open_fds(), threading.active_count()
    cancel = threading.Event()
    calls = []

    def progress(*c):
        calls.append(c)
        cancel.set()

    with pytest.raises(gb.LoadCancelled, match="cancelled"):
        gb.load(files[kind], progress=progress, cancel=cancel)
    assert calls == [(0, calls[0][1], "bytes")]
    assert _open_fds() == fds and threading.active_count() == threads
    assert isinstance(gb.LoadCancelled("x"), gb.Cancelled) and isinstance(gb.RenderCancelled("x"), gb.Cancelled)


@pytest.mark.parametrize("kind", ["event", "token"])
def test_cancel_set_before_the_load_reports_nothing(files, kind):
    cancel = gb.CancelToken() if kind == "token" else threading.Event()
    cancel.set()
    calls = []
    with pytest.raises(gb.LoadCancelled):
        gb.load(files["inria"], progress=lambda *c: calls.append(c), cancel=cancel)
    assert calls == []


@pytest.mark.parametrize("cancel", [object(), True, lambda: False])
def test_a_cancel_without_is_set_is_refused(files, cancel):
    """One line naming `cancel` and what it takes (not an AttributeError, not blamed on the file)."""
    with pytest.raises(
        gb.GBViewerError,
        match=r"^cancel: expected a gbviewer.CancelToken, a threading.Event or an "
        r"object with an is_set\(\) method",
    ) as exc:
        gb.load(files["inria"], cancel=cancel)
    assert not isinstance(exc.value, gb.SceneFormatError)


@pytest.mark.parametrize(
    "kind, unit", [(k, u) for k in KINDS for u in ("bytes", "splats") if u == "bytes" or k in SPLATS_REPORTED]
)
@pytest.mark.parametrize("error", [ValueError, OSError, KeyError, gb.GBViewerError])
def test_a_raising_progress_callback_is_not_blamed_on_the_file(files, kind, unit, error, small_chunks):
    """A progress callback that raises (midway, in either phase, with exceptions the loaders catch from the file):
    one CallbackError chained to it, not a SceneFormatError; nothing left open; the file still loads."""
    fds = _open_fds()

    def progress(done, total, u):
        if u == unit and done >= total // 2:
            raise error("from the callback")

    with pytest.raises(gb.CallbackError, match="^progress raised .*from the callback.*load was cancelled") as info:
        gb.load(files[kind], progress=progress)
    assert type(info.value.__cause__) is error and not isinstance(info.value, gb.SceneFormatError)
    del info  # its traceback holds the loader's frames (and their files) alive
    gc.collect()
    assert _open_fds() == fds
    same_scene(gb.load(files[kind]), gb.load(files[kind], cancel=gb.CancelToken()))


@pytest.mark.parametrize(
    "kind, unit",
    [
        (k, u)
        for k in ("inria", "ascii", "spz-gzip", "spz-zstd", "splat", "sog-zip")
        for u in ("bytes", "splats")
        if u == "bytes" or k in SPLATS_REPORTED
    ],
)
def test_cancel_midway_stops_within_a_chunk(files, kind, unit, small_chunks):
    """Set halfway through reading (a mapped PLY, ASCII lines, a gzip stream, a whole file, images) or decoding:
    the next chunk raises, so the last report is the one that set it."""
    fds = _open_fds()
    cancel = threading.Event()
    calls = []

    def progress(done, total, u):
        calls.append((done, total, u))
        if u == unit and done >= total // 2:
            cancel.set()

    with pytest.raises(gb.LoadCancelled):
        gb.load(files[kind], progress=progress, cancel=cancel)
    done, total, last_unit = calls[-1]
    assert last_unit == unit and total // 2 <= done < total and _open_fds() == fds


@pytest.mark.filterwarnings("ignore:`torch.jit:DeprecationWarning")  # the published format is TorchScript
def test_duplex_checkpoint_reports_its_anchor_bytes(tmp_path):
    pytest.importorskip("torch", reason="Duplex-GS checkpoints need torch")
    from test_duplex_checkpoint import hand_checkpoint

    path, _ = hand_checkpoint(tmp_path)
    calls = []
    gb.load(path, progress=lambda *c: calls.append(c))
    assert check_reports(calls) == {"bytes": 2} and calls[-1][0] == path.stat().st_size
