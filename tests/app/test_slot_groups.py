"""SlotThread groups: requests worked on together share a cancel token; a newer request of one slot stops the group
and the others go back to the queue (no result handed out for them), unless cleared or replaced."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

from gbviewer.app.slot_thread import SlotThread


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
        assert sorted((r.req.slot, r.req.n, r.cancelled) for r in out) == [("a", 0, False), ("b", 0, True),
                                                                            ("b", 1, False), ("c", 0, False)]
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
