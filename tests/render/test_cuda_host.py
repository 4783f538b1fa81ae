"""The CUDA driver's host-side decisions without a GPU: native/cuda/host_logic.h compiled with the host compiler
against a stand-in runtime (cuda_host_check.cpp): a device guard on a thread that never chose a device leaves no
context on device 0, a failed switch to a device marks that device (not the current one) failed, a stale view-weight
or cell upload leaves the current scene's data. And every device buffer of native/cuda/state.h is one that
release_buffers frees."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from native_builds import compile_check

REPO = Path(__file__).resolve().parents[2]
CASES = [
    "guard_on_a_fresh_thread_restores_nothing",
    "guard_restores_the_chosen_device",
    "guard_on_the_same_device_switches_nothing",
    "failed_switch_marks_the_target_device",
    "plain_switch_error_marks_nothing",
    "sticky_error_marks_the_current_device",
    "out_of_memory_is_not_fatal",
    "stale_derived_upload_keeps_the_data",
    "derived_upload_before_a_scene_is_refused",
    "current_derived_upload_clears_then_copies",
]


def test_host_logic_on_a_stand_in_runtime(tmp_path):
    exe = tmp_path / "cuda_host_check"
    compile_check(Path(__file__).with_name("cuda_host_check.cpp"), exe, [REPO / "native" / "cuda"], optimise=False)
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=30)
    assert run.returncode == 0 and run.stdout.split() == [w for c in CASES for w in ("ok", c)], run.stdout


def test_release_buffers_frees_every_device_buffer():
    """A buffer added to State is freed by release_buffers too (CudaRenderer.release: the CPU and GLSL backends
    free theirs)."""
    text = (REPO / "native" / "cuda" / "state.h").read_text()
    declared = set()
    for names in re.findall(r"^\s*Buf<[^>]+>\s+([^;]+);", text, re.M):
        for name in names.split(","):
            name = name.strip()
            m = re.fullmatch(r"(\w+)\[(\d+)\]", name)
            declared |= {f"{m[1]}[{i}]" for i in range(int(m[2]))} if m else {name}
    body = re.search(r"void release_buffers\(\) \{.*?free\((.*?)\);", text, re.S)
    assert body, "State::release_buffers not found"
    freed = {n.strip() for n in body[1].split(",")}
    assert len(declared) > 40 and freed == declared, (declared - freed, freed - declared)
