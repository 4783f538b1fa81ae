"""The GPU session's report (bench/gpu_session.py): OUT_DIR/report.txt, one line per piece and a table per piece
with rows, and report.json with the machine (Python, host, nvidia-smi's GPU, the cuda backend's availability), both
rewritten after every piece. Imported by gpu_session.py after it has put the checkout's gbviewer first on the path."""

from __future__ import annotations

import json
import os
import platform
import subprocess
import time
from pathlib import Path

from gbviewer.render import CudaRenderer


class Session:
    """The report being written: pieces in order, each {name, status, detail, data}; written after every piece."""

    def __init__(self, out: Path, deadline: float) -> None:
        self.out, self.deadline, self.pieces = out, deadline, []
        out.mkdir(parents=True, exist_ok=True)

    def left(self) -> float:
        return self.deadline - time.time()

    def add(self, name: str, status: str, detail: str, data: object = None) -> None:
        self.pieces.append(dict(name=name, status=status, detail=" ".join(detail.split()), data=data))
        self.write()

    def write(self) -> None:
        report = dict(machine=machine(), pieces=self.pieces)
        lines = [f"{p['name']}: {p['status']}" + (f" - {p['detail']}" if p["detail"] else "") for p in self.pieces]
        for p in self.pieces:
            if isinstance(p["data"], list) and p["data"] and isinstance(p["data"][0], dict):
                lines += ["", f"## {p['name']}", *table(p["data"])]
        for name, text in (
            ("report.json", json.dumps(report, indent=1, default=str)),
            ("report.txt", "\n".join(lines) + "\n"),
        ):
            tmp = self.out / f".{name}.tmp"
            tmp.write_text(text)
            os.replace(tmp, self.out / name)


def table(rows: list[dict]) -> list[str]:
    keys = list(rows[0])
    fmt = lambda v: f"{v:.3g}" if isinstance(v, float) else str(v)  # noqa: E731
    return [
        " | ".join(keys),
        " | ".join("---" for _ in keys),
        *(" | ".join(fmt(r.get(k, "")) for k in keys) for r in rows),
    ]


def machine() -> dict:
    smi = run_quiet(["nvidia-smi", "--query-gpu=name,driver_version,memory.total", "--format=csv,noheader"])
    return dict(
        python=platform.python_version(),
        host=platform.node(),
        gpu=smi or "nvidia-smi: none",
        cuda=CudaRenderer.available(),
    )


def run_quiet(cmd: list[str]) -> str:
    try:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=20).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""
