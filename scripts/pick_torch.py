"""Which torch `scripts/setup.sh --dev` installs for Duplex-GS checkpoints: the pinned release (the `duplex` extra of
pyproject.toml) as a CPU build, from wherever pip finds one (a local wheel, a configured index, or PyTorch's CPU index).
Prints pip's arguments for it, one a line, and exits 0; where pip would take the CUDA build (gigabytes of `nvidia-*`
packages) prints one line saying so, with the index and the size, and exits 1: the Duplex-GS tests then skip."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
import urllib.request
from pathlib import Path

CPU_INDEX = "https://download.pytorch.org/whl/cpu"  # PyTorch's own index of CPU-only builds


def pinned() -> str:
    extras = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())["project"]
    return next(r for r in extras["optional-dependencies"]["duplex"] if r.startswith("torch"))


def resolve(args: list[str]) -> list[dict]:
    """What `pip install args` would install here (pip's installation report), without installing it."""
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "install",
            "--dry-run",
            "--ignore-installed",
            "--quiet",
            "--timeout",
            "15",
            "--retries",
            "1",
            "--report",
            "-",
            *args,
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    if proc.returncode:
        raise RuntimeError(proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else f"exit {proc.returncode}")
    return json.loads(proc.stdout)["install"]


def size(url: str) -> int:
    """Bytes behind a download URL (0 where unknown)."""
    if url.startswith("file://"):
        return os.path.getsize(urllib.request.url2pathname(url[7:]))
    try:
        with urllib.request.urlopen(urllib.request.Request(url, method="HEAD"), timeout=10) as reply:
            return int(reply.headers.get("Content-Length") or 0)
    except (OSError, ValueError):
        return 0


def main() -> int:
    args = ["--extra-index-url", CPU_INDEX, pinned()]
    try:
        items = resolve(args)
    except (RuntimeError, subprocess.TimeoutExpired, json.JSONDecodeError) as exc:
        print(
            f"setup: torch is not installed: pip could not resolve {pinned()} ({exc}); Duplex-GS checkpoints and "
            "their tests need it",
            file=sys.stderr,
        )
        return 1
    torch = next(i for i in items if i["metadata"]["name"].lower() == "torch")
    cuda = [i for i in items if i["metadata"]["name"].lower().startswith(("nvidia-", "triton"))]
    if "+cpu" in torch["metadata"]["version"] or not cuda:
        print("\n".join(args))
        return 0
    url = torch["download_info"]["url"]
    total = sum(size(i["download_info"]["url"]) for i in [torch, *cuda])
    where = url.split("/packages/")[0] if "/packages/" in url else url.rsplit("/", 1)[0]
    print(
        f"setup: torch is not installed: {pinned()} from {where} is its CUDA build ({len(cuda)} nvidia/triton "
        f"packages, {total / 2**30:.1f} GiB to download): neither {CPU_INDEX} nor a local wheel gave a CPU "
        "build; Duplex-GS checkpoints and their tests need it: pip install 'gbviewer[duplex]' takes the "
        "CUDA build, or PIP_FIND_LINKS=DIR with a CPU wheel takes that",
        file=sys.stderr,
    )
    return 1


if __name__ == "__main__":
    sys.exit(main())
