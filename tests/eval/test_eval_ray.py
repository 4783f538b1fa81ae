"""`gbviewer eval --ray`: each task's CPU request shares the cluster's CPUs among the tasks (on a stand-in for Ray,
which records what is asked); a signal reaches the caller's handler through Ray's handlers and waits (on the
stand-in), and SIGTERM while a local Ray instance starts ends the run with the one line and the status a local
run gives, without Ray's notices or stack dumps."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from helpers import skip_or_fail

import gbviewer as gb
from gbviewer.eval import cluster
from gbviewer.eval.cluster import run_on_ray, task_cpus
from gbviewer.eval.tasks import ViewTask

PACKAGE_ROOT = Path(gb.__file__).resolve().parents[1]


@pytest.mark.parametrize(
    "threads, tasks, nodes, expected",
    [
        (0, 9, [2], 1),  # 2 cores, 9 views: two tasks at once, as --workers 2
        (0, 1, [2], 2),  # one task takes the node
        (0, 4, [64], 16),  # four tasks share 64 CPUs
        (0, 3, [32, 32], 16),  # 21 each would fit one task per node: 2 of the 3 at once
        (0, 100, [8, 8], 1),
        (4, 9, [2], 2),  # --threads 4 on 2-CPU nodes: a task needs a node that can hold it
        (3, 9, [16], 3),
        (0, 0, [], 1),
        (8, 9, [0, 16], 8),  # a head node without CPUs runs no task: it capped every task at 1 CPU
        (0, 4, [0, 16], 4),
        (0, 2, [2, 64], 32),  # both tasks fit the large node
    ],
)
def test_task_cpus_share_the_cluster(threads, tasks, nodes, expected):
    assert task_cpus(threads, tasks, nodes) == expected


class FakeRay(SimpleNamespace):
    """The parts of Ray `run_on_ray` uses; runs each task in this process and records the options asked for."""

    def __init__(self, cpus: list[float], signal_in_wait: bool = False):
        super().__init__(
            asked={},
            cpus=cpus,
            signal_in_wait=signal_in_wait,
            exited=[],
            exceptions=SimpleNamespace(RayTaskError=RuntimeError),
            _private=SimpleNamespace(
                utils=SimpleNamespace(set_sigterm_handler=self._set_handler), ray_constants=SimpleNamespace()
            ),
        )

    def _set_handler(self, handler):
        signal.signal(signal.SIGTERM, handler)

    def init(self, **kwargs):  # as ray.init: its own SIGTERM handler (sys.exit(15))
        self._private.utils.set_sigterm_handler(lambda signum, frame: self.exited.append(signum))

    def shutdown(self):
        pass

    def cluster_resources(self):
        return {"CPU": sum(self.cpus)}

    def nodes(self):
        return [{"Alive": True, "Resources": {"CPU": c}} for c in self.cpus]

    def remote(self, fn):
        fake = self

        class Remote:
            def options(self, **kwargs):
                fake.asked = kwargs
                return self

            def remote(self, task):
                return task

        return Remote()

    def wait(self, pending, num_returns):
        if self.signal_in_wait:
            try:
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(10)  # the handler interrupts this
            except KeyboardInterrupt:
                raise KeyboardInterrupt from None  # Ray's waits raise a plain one, whatever the handler raised
            raise AssertionError("the SIGTERM handler did not interrupt the wait")
        return pending[:num_returns], pending[num_returns:]

    def get(self, refs):
        return refs


def test_run_on_ray_asks_for_the_shared_cpus(monkeypatch):
    """On a 2-CPU node, 9 tasks each ask for 1 CPU and render with 1 thread (they asked for 4 and ran one at a
    time, 2.4x slower than --workers 2)."""
    ray = FakeRay([2.0])
    monkeypatch.setattr(cluster, "require", lambda *a: ray)
    tasks = [ViewTask("s.ply", 0, j, None, (), (1.0,), (0.0, 0.0, 0.0), "cpu") for j in range(9)]
    done = run_on_ray(tasks, "local", lambda n: None)
    assert ray.asked == {"num_cpus": 1} and [t.threads for t in done] == [1] * 9


class Stop(Exception):
    """What the caller's SIGTERM handler raises (the command line's raises `Terminated`)."""


def test_a_signal_during_rays_wait_reaches_the_callers_handler(monkeypatch):
    """ray.init's SIGTERM handler is not installed, and a SIGTERM during a wait, which Ray turns into a plain
    KeyboardInterrupt, reaches the handler that was there (the command line's: one line, 143); it is back after."""
    ray = FakeRay([2.0], signal_in_wait=True)
    monkeypatch.setattr(cluster, "require", lambda *a: ray)

    def handler(signum, frame):
        raise Stop(signum)

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        tasks = [ViewTask("s.ply", 0, j, None, (), (1.0,), (0.0, 0.0, 0.0), "cpu") for j in range(3)]
        with pytest.raises(Stop) as stop:
            run_on_ray(tasks, "local", lambda n: None)
        assert stop.value.args == (signal.SIGTERM,) and ray.exited == []
        assert signal.getsignal(signal.SIGTERM) is handler
    finally:
        signal.signal(signal.SIGTERM, previous)


def test_sigterm_while_ray_starts_is_one_line(capture, tmp_path):
    """SIGTERM as the local Ray instance starts: held until ray.init returns (an interrupted one leaves Ray's
    agent processes behind), then exit 143 with the command line's one line (Ray's own handler exited 15, its
    core worker printed a stack dump and aborted), and no token-authentication notice."""
    try:
        import ray  # noqa: F401
    except ImportError:
        skip_or_fail("ray is not installed (pip install 'gbviewer[ray]')")
    ray_tmp = Path(tempfile.mkdtemp(prefix="ray", dir="/tmp"))  # short: Ray's socket paths must fit 107 bytes
    env = {
        **os.environ,
        "PYTHONPATH": str(PACKAGE_ROOT),
        "XDG_CACHE_HOME": str(tmp_path / "xdg"),
        "RAY_USAGE_STATS_ENABLED": "0",
        "RAY_TMPDIR": str(ray_tmp),
    }
    cache = tmp_path / "c"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "gbviewer",
            "eval",
            str(gb.DEFAULT_SCENE),
            "--data",
            str(capture),
            "--modes",
            "scalar,gaussian_blending",
            "--rates",
            "1,1/2",
            "--backend",
            "cpu",
            "--split",
            "all",
            "--cache",
            str(cache),
            "--ray",
            "local",
        ],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    sessions = ray_tmp / "ray"
    try:
        deadline = time.monotonic() + 180
        while (
            not (sessions.is_dir() and any(sessions.glob("session_*")))
            and proc.poll() is None
            and time.monotonic() < deadline
        ):
            time.sleep(0.05)
        assert proc.poll() is None and any(sessions.glob("session_*")), "Ray never started"
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
        shutil.rmtree(ray_tmp, ignore_errors=True)
    assert proc.returncode == 128 + signal.SIGTERM and err == "gbviewer: interrupted (SIGTERM)\n", err[-3000:]
    assert not (cache.is_dir() and any(cache.iterdir()))  # no task ran
