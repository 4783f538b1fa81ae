"""Every fuzzing seed and every input the loader fuzzer (tools/fuzz_loaders.py) ever flagged, replayed with its
own check: a scene with finite values or one clear line, never a traceback or a numpy warning."""

from __future__ import annotations

from pathlib import Path

import fuzz_loaders  # tools/, on sys.path through conftest
import pytest

FUZZ = Path(__file__).parent / "fuzz"

SEEDS = sorted((FUZZ / "seeds").glob("*/*"))
CRASHES = sorted((FUZZ / "crashes").glob("*"))


@pytest.mark.parametrize("path", SEEDS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_seed_loads(path):
    assert fuzz_loaders.check_load(path, path.parent.name) == "ok"


@pytest.mark.parametrize("path", CRASHES, ids=lambda p: p.name[:24])
@pytest.mark.filterwarnings("ignore:.*dropped.*splats:UserWarning")
def test_former_crash_is_handled(path):
    assert fuzz_loaders.check_load(path, path.name.split("-crash-")[0]) in ("ok", "error")


def test_there_is_something_to_replay():
    assert len(SEEDS) >= 8 and CRASHES
