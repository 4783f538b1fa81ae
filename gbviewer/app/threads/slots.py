"""The viewer's background threads: each works on the newest request per slot (a newer request of a slot replaces
the one still waiting), in the order and with the cancelling its `SlotPolicy` gives. The render thread
(`worker.RenderWorker`), the analysis (`analysis_worker`) and the inspector's traces (`inspector.TraceThread`) are
one each."""

from __future__ import annotations

import os
import sys
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Hashable

from ...core.cancel import CancelToken
from ...model.scene import Scene
from ...render import create_renderer
from ...render.choice import FALLBACK

RENDER_NICE = 10  # added to a render thread's (and its OpenMP threads') niceness: the UI gets a core when it asks


def lower_priority(amount: int = RENDER_NICE) -> None:
    """Raise the calling thread's niceness by `amount` (Linux, where a thread is a task; elsewhere it would renice
    the whole process, so nothing): the threads it starts later, OpenMP's and Mesa's included, inherit it. For the
    threads that render or load beside the window."""
    if not sys.platform.startswith("linux"):
        return
    try:
        tid = threading.get_native_id()
        os.setpriority(os.PRIO_PROCESS, tid, min(19, os.getpriority(os.PRIO_PROCESS, tid) + amount))
    except OSError:
        pass


@dataclass(frozen=True)
class SlotPolicy:
    """Which waiting slot goes next: the one whose request has waited longest. `cancel_running`: a newer request of
    the running slot sets the running one's cancel event (else the running one finishes)."""

    cancel_running: bool = True

    def rank(self, request: Any, seq: int, served: float) -> tuple:
        """The waiting request with the smallest rank goes next; `seq`: its submission number, `served`: when its
        slot last finished (perf_counter, 0 never)."""
        return (seq,)

    def cancels(self, running: Any, newer: Any) -> bool:
        """Whether `newer`, of the running request's slot, stops `running`."""
        return self.cancel_running


class SlotThread:
    """One thread on the newest request per slot (`request.slot`), ordered by `policy`. A subclass defines
    `_work(request, cancel) -> result or None` (None: nothing to hand out, e.g. cancelled); `_renderer_for(scene)`
    gives it a renderer of `backend` of its own with `scene` uploaded. `nice`: added to the thread's niceness.
    `on_result`: called from the thread after a result is handed out.

    A subclass may work on several requests at once: `_companions(first, waiting)` names the waiting requests that
    go with the first (e.g. panes rendered together), `_work_all(requests, cancel)` returns a result per request.
    They share one cancel token: a newer request of one slot stops them all, and the others (`.cancelled` results
    whose slot has nothing newer) go back to the queue."""

    NAME = "gbviewer-slots"

    def __init__(
        self,
        policy: SlotPolicy = SlotPolicy(),
        backend: str = FALLBACK,
        nice: int = 0,
        on_result: Callable[[], None] | None = None,
    ) -> None:
        self.policy, self._backend, self._nice, self._on_result = policy, backend, nice, on_result
        self._lock = threading.Condition()
        self._pending: dict[Hashable, tuple[int, Any]] = {}  # slot -> (seq, request)
        self._running: list = []  # the requests being worked on
        self._cancel = CancelToken()  # the running request's: the native loop reads its flag directly
        self._results: list = []
        self._served: dict[Hashable, float] = {}
        self._seq = 0
        self._cancelled_by: set[Hashable] = set()  # slots that stopped the running requests
        self._generation = 0  # counts clear/forget/stop: running requests of an older one are not requeued
        self._stop = False
        self._wakes: set[str] = set()  # why the thread was woken without a request ("forget", a subclass's own)
        self._renderer = None
        self._scene: Scene | None = None  # the scene uploaded to the renderer
        self.done = 0  # results handed out
        self.dropped = 0  # requests replaced before they started
        self._thread = threading.Thread(target=self._loop, name=self.NAME, daemon=True)
        self._thread.start()

    # ---- caller's side -----------------------------------------------------------------------------------------

    def submit(self, request) -> None:
        """Queue `request`, replacing its slot's waiting one; cancel its slot's running one where the policy says."""
        self.submit_all([request])

    def submit_all(self, requests: list) -> None:
        """`submit` each of `requests` at once: the thread sees them together (to work on them as companions)."""
        with self._lock:
            for request in requests:
                self._seq += 1
                self.dropped += request.slot in self._pending
                self._pending[request.slot] = (self._seq, request)
                for running in self._running:
                    if running.slot == request.slot and self.policy.cancels(running, request):
                        self._cancelled_by.add(request.slot)
                        self._cancel.set()
            self._lock.notify()

    def cancel(self, slot: Hashable) -> None:
        """Forget `slot`'s waiting request and stop its running one."""
        with self._lock:
            self._pending.pop(slot, None)
            if any(running.slot == slot for running in self._running):
                self._cancelled_by.add(slot)
                self._cancel.set()

    def results(self) -> list:
        with self._lock:
            out, self._results = self._results, []
        return out

    def busy(self, slot: Hashable | None = None) -> bool:
        """Whether `slot` (or any slot) has a request waiting or being worked on."""
        with self._lock:
            if slot is None:
                return bool(self._pending) or bool(self._running)
            return slot in self._pending or any(running.slot == slot for running in self._running)

    def clear(self) -> None:
        """Drop what is waiting."""
        with self._lock:
            self._pending.clear()
            self._generation += 1

    def forget(self) -> None:
        """Drop what is waiting, stop what runs, and free the scene (a new scene is open)."""
        with self._lock:
            self._pending.clear()
            self._generation += 1
            self._cancel.set()
        self._wake("forget")

    def stop(self, timeout: float = 30.0) -> None:
        with self._lock:
            self._stop = True
            self._pending.clear()
            self._generation += 1
            self._cancel.set()
            self._lock.notify()
        self._thread.join(timeout)

    def _wake(self, why: str) -> None:
        """Run one round of the loop without a request (`_between` gets `why`)."""
        with self._lock:
            self._wakes.add(why)
            self._lock.notify()

    # ---- the thread --------------------------------------------------------------------------------------------

    def _work(self, request, cancel: CancelToken):
        raise NotImplementedError

    def _companions(self, first, waiting: list) -> list:
        """Of the `waiting` requests (in rank order), those worked on together with `first`: none by default."""
        return []

    def _work_all(self, requests: list, cancel: CancelToken) -> list:
        """A result (or None) per request of `requests` (one, or `first` and its companions)."""
        return [self._work(requests[0], cancel)]

    def _start(self) -> None:
        """First thing in the thread."""

    def _between(self, wakes: set[str], request) -> None:
        """Each round, before `request` (None: woken for `wakes` alone) is worked on."""
        if "forget" in wakes:
            self._release()

    def _release(self) -> None:
        """Free the renderer and the scene (and, in a subclass, what it keeps for that scene)."""
        self._renderer = self._scene = None

    def _renderer_for(self, scene: Scene):
        if self._scene is not scene:
            self._release()
            self._renderer = create_renderer(self._backend)
            self._renderer.upload(scene)
            self._scene = scene
        return self._renderer

    def _next(self) -> list:
        """The waiting request the policy ranks first and its companions (taken off the queue), with a fresh cancel
        token."""

        def rank(slot: Hashable) -> tuple:
            seq, request = self._pending[slot]
            return self.policy.rank(request, seq, self._served.get(slot, 0.0))

        slots = sorted(self._pending, key=rank)
        first = self._pending.pop(slots[0])[1]
        companions = self._companions(first, [self._pending[s][1] for s in slots[1:]])
        for request in companions:
            del self._pending[request.slot]
        self._running, self._cancel, self._cancelled_by = [first, *companions], CancelToken(), set()
        return self._running

    def _requeue(self, requests: list, results: list, seqs: dict, generation: int) -> set:
        """Under the lock: put back the requests of a stopped group that nothing replaced or dropped; their slots."""
        if len(requests) < 2 or generation != self._generation:
            return set()
        back = {request.slot for request, result in zip(requests, results) if getattr(result, "cancelled", False)}
        back -= self._cancelled_by | set(self._pending)
        for request in requests:
            if request.slot in back:
                self._pending[request.slot] = (seqs.get(request.slot, 0), request)
        return back

    def _loop(self) -> None:
        if self._nice:
            lower_priority(self._nice)
        self._start()
        while True:
            with self._lock:
                while not self._pending and not self._stop and not self._wakes:
                    self._lock.wait()
                if self._stop:
                    break
                wakes, self._wakes = self._wakes, set()
                seqs = {slot: seq for slot, (seq, _) in self._pending.items()}
                requests = self._next() if self._pending else []
                cancel, generation = self._cancel, self._generation
            self._between(wakes, requests[0] if requests else None)
            if not requests:
                continue
            results = self._work_all(requests, cancel)
            with self._lock:
                self._running = []
                back = self._requeue(requests, results, seqs, generation)
                now = time.perf_counter()
                for request, result in zip(requests, results):
                    self._served[request.slot] = now
                    if result is not None and request.slot not in back:
                        self._results.append(result)
                        self.done += 1
            if any(result is not None for result in results) and self._on_result is not None:
                self._on_result()
        self._finish()

    def _finish(self) -> None:
        """Last thing in the thread."""
        self._release()
