"""The evaluation's tasks on a Ray cluster (the optional `ray` extra): one Ray task per scene view, each worker
process keeping its scenes loaded (`tasks._scene`), results gathered as they finish. Every node needs gbviewer
installed and the scenes, photos and cache folder at the same paths (a shared file system)."""

from __future__ import annotations

import ipaddress
import logging
import socket
from dataclasses import replace
from typing import Callable

from ..errors import GBViewerError
from ..extras import require
from ..render import AUTO, BACKENDS
from .tasks import ViewResult, ViewTask, run_task

TASK_CPUS = 4  # CPUs (render threads) per Ray task unless --threads says: a node runs cores / 4 tasks at once
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
        raise GBViewerError(f"{what}: nothing accepts a connection at {host} port {port} within "
                            f"{CONNECT_TIMEOUT_S:g} s ({exc.strerror or exc}); is the Ray head running?") from None


def renders_on_device(backend: str) -> bool:
    """Whether tasks of `backend` want a GPU: auto (a worker with one picks it) or a backend off the host."""
    return backend == AUTO or (backend in BACKENDS and not BACKENDS[backend].capabilities.host)


def run_on_ray(tasks: list[ViewTask], address: str, advance: Callable[[int], None]) -> list[ViewResult]:
    """Run `tasks` on the Ray cluster at `address` (host:port, ray://host:port or auto; local: start a Ray
    instance in this process for the run). Where the cluster has GPUs and the backend is auto or
    one that renders off the host (`Capabilities.host` false), each task takes one GPU; else it takes the tasks' `threads` CPUs (0: TASK_CPUS, at most the
    smallest node's count) and renders with as many threads. `run_eval` has checked the address (`check_address`)."""
    ray = require("ray", "ray", "--ray")
    try:
        ray.init(address=None if address == "local" else address, include_dashboard=False,
                 logging_level=logging.WARNING, configure_logging=True)
    except (ConnectionError, RuntimeError, ValueError) as exc:
        raise GBViewerError(f"--ray {address}: cannot connect ({' '.join(str(exc).split())[:200]})") from None
    try:
        gpus = ray.cluster_resources().get("GPU", 0) > 0 and bool(tasks) and renders_on_device(tasks[0].backend)
        smallest = min((n["Resources"].get("CPU", 1) for n in ray.nodes() if n["Alive"]), default=1)
        cpus = (tasks[0].threads if tasks else 0) or max(1, min(TASK_CPUS, int(smallest)))
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
    finally:
        ray.shutdown()
