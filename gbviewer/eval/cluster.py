"""The evaluation's tasks on a Ray cluster (the optional `ray` extra): one Ray task per scene view, each worker
process keeping its scenes loaded (`tasks._scene`), results gathered as they finish. Every node needs gbviewer
installed and the scenes, photos and cache folder at the same paths (a shared file system)."""

from __future__ import annotations

import ipaddress
import logging
import signal
import socket
import threading
from contextlib import contextmanager
from dataclasses import replace
from typing import Callable, Iterator

from ..core.errors import GBViewerError
from ..core.extras import require
from ..render import AUTO, BACKENDS
from .tasks import ViewResult, ViewTask, run_task

CONNECT_TIMEOUT_S = 5.0  # the TCP connect that checks a cluster address before ray.init (which retries for long)


def check_address(address: str) -> None:
    """A one-line `GBViewerError` unless `address` is local, auto, or [ray://]host:port whose host resolves and
    whose port accepts a TCP connection within CONNECT_TIMEOUT_S (ray.init would retry and warn for minutes)."""
    if address in ("local", "auto"):
        return
    what = f"--ray {address}"
    host, colon, port = address.removeprefix("ray://").rpartition(":")
    host = host.strip("[]")
    if not colon or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise GBViewerError(f"{what}: expected host:port (port 1..65535), ray://host:port, auto or local")
    if all(c.isdigit() or c == "." for c in host):  # dotted numbers: an IPv4 address, never a name to look up
        try:
            ipaddress.IPv4Address(host)
        except ValueError:
            raise GBViewerError(f"{what}: {host} is not a valid IPv4 address") from None
    try:
        infos = socket.getaddrinfo(host, int(port), type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        raise GBViewerError(f"{what}: cannot resolve the host {host!r} ({exc})") from None
    try:
        socket.create_connection(infos[0][4][:2], timeout=CONNECT_TIMEOUT_S).close()
    except OSError as exc:
        raise GBViewerError(
            f"{what}: nothing accepts a connection at {host} port {port} within "
            f"{CONNECT_TIMEOUT_S:g} s ({exc.strerror or exc}); is the Ray head running?"
        ) from None


def renders_on_device(backend: str) -> bool:
    """Whether tasks of `backend` want a GPU: auto (a worker with one picks it) or a backend off the host."""
    return backend == AUTO or (backend in BACKENDS and not BACKENDS[backend].capabilities.host)


def task_cpus(threads: int, tasks: int, node_cpus: list[float]) -> int:
    """The CPUs each of `tasks` Ray tasks asks for (and renders with) on alive nodes of `node_cpus` CPUs:
    `threads` when given, else the most that still runs every task at once (each node running as many as its
    CPUs hold), 1 where even that cannot; at most the largest node's count (else no node could run a task). Nodes
    without a whole CPU (a head started with --num-cpus=0, as Ray advises for large clusters) run no task and do
    not count: they capped every task at 1 CPU, --threads included."""
    usable = [int(n) for n in node_cpus if n >= 1] or [1]
    if threads:
        return min(threads, max(usable))
    return next((c for c in range(max(usable), 1, -1) if sum(n // c for n in usable) >= tasks), 1)


class _NoTokenNotice(logging.Filter):
    """Drops Ray's warning that token authentication is enabled: the safe state (Ray's default for the instance
    `--ray local` starts; for a cluster, the token in ~/.ray/auth_token), nothing for the user to do."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.funcName != "_warn_token_auth_enabled"


@contextmanager
def _signals_kept(ray) -> Iterator[Callable[[], None]]:
    """Keep this process's SIGTERM and SIGHUP handlers (the command line's: one line, exit 128 + N) through a Ray
    run: ray.init would install its own SIGTERM handler (exit status 15) and its core worker a failure handler
    (a stack dump), and Ray's waits turn whatever a signal handler raises into a plain KeyboardInterrupt. Here a
    signal is noted, held until ray.init returns (an interrupted one leaves Ray's agent processes behind), then
    interrupts Ray; once Ray has unwound, it goes to the handler that was there. Yields the function to call
    when ray.init has returned."""
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGHUP)}
    previous = {sig: h for sig, h in previous.items() if callable(h)}
    if threading.current_thread() is not threading.main_thread() or not previous:
        yield lambda: None
        return
    received: list[int] = []
    started = [False]

    def note(signum: int, frame: object) -> None:
        received.append(signum)
        if started[0]:
            raise KeyboardInterrupt

    def after_init() -> None:
        for sig in previous:  # again: whatever ray.init installed goes
            signal.signal(sig, note)
        started[0] = True
        if received:
            raise KeyboardInterrupt

    utils, constants = ray._private.utils, ray._private.ray_constants
    ray_sets, dumps_off = utils.set_sigterm_handler, getattr(constants, "RAY_DISABLE_FAILURE_SIGNAL_HANDLER", False)
    utils.set_sigterm_handler = lambda handler: None
    constants.RAY_DISABLE_FAILURE_SIGNAL_HANDLER = True  # read as ray.init starts this process's core worker
    for sig in previous:
        signal.signal(sig, note)
    try:
        yield after_init
    except KeyboardInterrupt:
        if received:
            previous[received[0]](received[0], None)
        raise
    finally:
        utils.set_sigterm_handler, constants.RAY_DISABLE_FAILURE_SIGNAL_HANDLER = ray_sets, dumps_off
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def run_on_ray(tasks: list[ViewTask], address: str, advance: Callable[[int], None]) -> list[ViewResult]:
    """Run `tasks` on the Ray cluster at `address` (host:port, ray://host:port or auto; local: start a Ray
    instance in this process for the run). Where the cluster has GPUs and the backend is auto or
    one that renders off the host (`Capabilities.host` false), each task takes one GPU; else it takes
    `task_cpus` CPUs and renders with as many threads. `run_eval` has checked the address (`check_address`)."""
    ray = require("ray", "ray", "--ray")
    notice = logging.getLogger("ray._private.authentication.authentication_token_setup")
    quiet = _NoTokenNotice()
    with _signals_kept(ray) as after_init:
        try:
            notice.addFilter(quiet)
            try:
                ray.init(
                    address=None if address == "local" else address,
                    include_dashboard=False,
                    logging_level=logging.WARNING,
                    configure_logging=True,
                )
            except (ConnectionError, RuntimeError, ValueError) as exc:
                raise GBViewerError(f"--ray {address}: cannot connect ({' '.join(str(exc).split())[:200]})") from None
            finally:
                notice.removeFilter(quiet)
                after_init()
            return _run(ray, tasks, advance)
        finally:
            ray.shutdown()  # also where ray.init failed part way: what it started would outlive this process


def _run(ray, tasks: list[ViewTask], advance: Callable[[int], None]) -> list[ViewResult]:
    """The tasks on the connected cluster, results in `tasks`' order."""
    gpus = ray.cluster_resources().get("GPU", 0) > 0 and bool(tasks) and renders_on_device(tasks[0].backend)
    nodes = [n["Resources"].get("CPU", 1) for n in ray.nodes() if n["Alive"]]
    cpus = task_cpus(tasks[0].threads if tasks else 0, len(tasks), nodes)
    remote = ray.remote(run_task).options(**({"num_gpus": 1, "num_cpus": 1} if gpus else {"num_cpus": cpus}))
    refs = [remote.remote(replace(t, threads=cpus)) for t in tasks]
    pending = list(refs)
    while pending:
        done, pending = ray.wait(pending, num_returns=1)
        advance(len(done))
    try:
        return ray.get(refs)
    except ray.exceptions.RayTaskError as exc:
        cause = exc.cause if isinstance(exc.cause, GBViewerError) else None
        raise GBViewerError(str(cause) if cause else f"a Ray task failed: {str(exc).splitlines()[0]}") from None
