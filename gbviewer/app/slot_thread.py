"""A background thread that works on the newest request per slot, with a CPU renderer of its own: the analysis
(differences, references, PSNR) and the inspector's traces run on one each, beside the render thread."""

from __future__ import annotations

import threading
from typing import Any, Hashable

from ..render import create_renderer
from ..scene import Scene


class SlotThread:
    """One thread on the newest request per slot (`request.slot`), the longest-waiting slot first. A subclass
    defines `_work(request, cancel)`: the result to hand out, or None (cancelled: a newer request of its slot came,
    when `CANCELS_RUNNING`); `_renderer_for(scene)` gives it the thread's CPU renderer with `scene` uploaded."""

    NAME = "gbviewer-slots"
    CANCELS_RUNNING = True  # a newer request of the running slot sets the running one's cancel event

    def __init__(self) -> None:
        self._lock = threading.Condition()
        self._pending: dict[Hashable, Any] = {}
        self._running: Hashable | None = None
        self._cancel = threading.Event()
        self._results: list = []
        self._stop = self._forget = False
        self._renderer = None
        self._scene: Scene | None = None  # the scene uploaded to the renderer
        self.done = 0  # results handed out
        self._thread = threading.Thread(target=self._loop, name=self.NAME, daemon=True)
        self._thread.start()

    def submit(self, request) -> None:
        """Queue `request`, replacing its slot's waiting one."""
        with self._lock:
            self._pending.pop(request.slot, None)
            self._pending[request.slot] = request
            if self.CANCELS_RUNNING and self._running == request.slot:
                self._cancel.set()
            self._lock.notify()

    def results(self) -> list:
        with self._lock:
            out, self._results = self._results, []
        return out

    def busy(self) -> bool:
        with self._lock:
            return bool(self._pending) or self._running is not None

    def clear(self) -> None:
        """Drop what is waiting."""
        with self._lock:
            self._pending.clear()

    def forget(self) -> None:
        """Drop what is waiting, stop what runs, and free the scene (a new scene is open)."""
        with self._lock:
            self._pending.clear()
            self._cancel.set()
            self._forget = True
            self._lock.notify()

    def stop(self, timeout: float = 30.0) -> None:
        with self._lock:
            self._stop = True
            self._pending.clear()
            self._cancel.set()
            self._lock.notify()
        self._thread.join(timeout)

    def _work(self, request, cancel: threading.Event):
        raise NotImplementedError

    def _release(self) -> None:
        """Free the renderer and the scene (and, in a subclass, what it keeps for that scene)."""
        self._renderer = self._scene = None

    def _renderer_for(self, scene: Scene):
        if self._scene is not scene:
            self._release()
            self._renderer = create_renderer("cpu")
            self._renderer.upload(scene)
            self._scene = scene
        return self._renderer

    def _loop(self) -> None:
        while True:
            with self._lock:
                while not self._pending and not self._stop and not self._forget:
                    self._lock.wait()
                if self._stop:
                    break
                if self._forget:
                    self._forget = False
                    self._release()
                    continue
                slot = next(iter(self._pending))
                request = self._pending.pop(slot)
                self._running, self._cancel = slot, threading.Event()
                cancel = self._cancel
            result = self._work(request, cancel)
            with self._lock:
                self._running = None
                if result is not None:
                    self._results.append(result)
                    self.done += 1
        self._release()
