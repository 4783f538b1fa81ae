"""SlotThread groups: requests worked on together share a cancel token; a newer request of one slot stops the group
and the others go back to the queue (no result handed out for them), unless cleared or replaced."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

from gbviewer.app.threads.slots import SlotThread


@dataclass
class Req:
    slot: str
    n: int


@dataclass
class Res:
    req: Req
    cancelled: bool


class Grouping(SlotThread):
    def __init__(self) -> None:
        self.groups: list[list[tuple[str, int]]] = []
        self.started = threading.Event()
        self.hold = threading.Event()  # the first group waits for its cancel while this is clear
        super().__init__()

    def _companions(self, first, waiting):
        return list(waiting)

    def _work_all(self, requests, cancel):
        self.groups.append([(r.slot, r.n) for r in requests])
        self.started.set()
        t0 = time.time()
        while not self.hold.is_set() and not cancel.is_set() and time.time() - t0 < 30:
            time.sleep(0.005)
        return [Res(r, cancel.is_set()) for r in requests]


def wait_for(pred, timeout=30.0):
    t0 = time.time()
    while not pred() and time.time() - t0 < timeout:
        time.sleep(0.005)
    assert pred()


def test_a_newer_request_restarts_the_group_with_the_others_requeued():
    t = Grouping()
    try:
        with t._lock:  # queue three before the thread takes any
            for s in "abc":
                t._seq += 1
                t._pending[s] = (t._seq, Req(s, 0))
            t._lock.notify()
        t.started.wait(30)
        assert sorted(t.groups[0]) == [("a", 0), ("b", 0), ("c", 0)]
        t.hold.set()  # the next group runs through
        t.submit(Req("b", 1))  # stops the group: a and c go back, b's newer request replaces it
        wait_for(lambda: not t.busy())
        assert sorted(t.groups[1]) == [("a", 0), ("b", 1), ("c", 0)]
        out = t.results()
        assert sorted((r.req.slot, r.req.n, r.cancelled) for r in out) == [
            ("a", 0, False),
            ("b", 0, True),
            ("b", 1, False),
            ("c", 0, False),
        ]
    finally:
        t.stop()


def test_a_cleared_or_cancelled_group_is_not_requeued():
    t = Grouping()
    try:
        for s in "ab":
            t.submit(Req(s, 0))
        t.started.wait(30)
        t.clear()
        t.cancel("a")
        wait_for(lambda: not t.busy())
        assert len(t.groups) == 1
        assert all(r.cancelled for r in t.results())
    finally:
        t.stop()


def test_the_render_thread_renders_the_panes_of_one_camera_together(bundled_scene):
    """Two progressive panes of one camera, submitted together: one render_many (the second frame reuses the first's
    stage), the second pane's first tiles posted before the first pane's last ones (interleaved tiles), both
    frames equal to single renders; a preview groups only with previews, a pane of another camera with neither."""
    import numpy as np

    import gbviewer as gb
    from gbviewer.app.frames.refine import companions
    from gbviewer.app.threads.worker import RenderJob, RenderWorker
    from gbviewer.render import RenderSettings

    cam = gb.orbit_camera(bundled_scene, width=640, height=480)
    specs = ("scalar:2", "gaussian_blending:2")
    jobs = [
        RenderJob((k, "a"), bundled_scene, cam, RenderSettings.parse(s), "cpu", progressive=True)
        for k, s in enumerate(specs)
    ]
    other = RenderJob((2, "a"), bundled_scene, cam.at_sampling_rate(0.5), RenderSettings(), "cpu")
    preview = RenderJob((3, "a"), bundled_scene, cam, RenderSettings(), "cpu", preview=True)
    assert companions(jobs[0], [jobs[1], other, preview]) == [jobs[1]] and companions(preview, jobs) == []
    previews = [RenderJob((k, "a"), bundled_scene, cam, RenderSettings(lod=2.0), "cpu", preview=True) for k in (4, 5)]
    assert companions(previews[0], [*jobs, previews[1], other]) == [previews[1]]  # the panes' previews together
    w = RenderWorker()
    try:
        w.submit_all(jobs)
        out, t0 = [], time.time()
        while sum(r.stage == "final" for r in out) < 2 and time.time() - t0 < 120:
            out += w.results()
            time.sleep(0.005)
    finally:
        w.stop()
    finals = {r.job.slot: r.frame for r in out if r.stage == "final"}
    assert [finals[(k, "a")].stats.stage_reused for k in range(2)] == [False, True]
    # one render: the second pane's first tiles are posted before the first pane's final (alone it would come after)
    order = [(r.job.slot[0], r.stage) for r in out if r.stage in ("partial", "final")]
    assert (1, "partial") in order and order.index((1, "partial")) < order.index((0, "final")), order
    for k, s in enumerate(specs):
        ref = gb.render(bundled_scene, cam, *s.split(":")[:1], supersample=2)
        np.testing.assert_array_equal(finals[(k, "a")].rgb, ref.rgb)
