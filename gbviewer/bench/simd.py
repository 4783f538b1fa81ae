"""The CPU backend's SIMD paths as the benchmark measures them: which this CPU runs, the one in use, switching,
the exp throughput per path (gbviewer._native.simd_paths / simd, testing.set_simd / exp_rate)."""

from __future__ import annotations

import os

from ..core.errors import GBViewerError

SIMD_NAMES = ("scalar", "avx2", "avx512")  # the CPU module's blend paths (GBVIEWER_SIMD)
EXP_RATE_N = 1 << 22  # exp evaluations per exp_rate call


def _native():
    """The CPU module, with its SIMD API (simd_paths, simd; testing.set_simd, testing.exp_rate)."""
    from .. import _native

    if not hasattr(_native, "testing"):
        raise GBViewerError(
            f"{_native.__file__} predates the renderer class (no _native.testing): rebuild it (pip install .)"
        )
    return _native


def simd_paths() -> list[str]:
    """The SIMD paths of the CPU backend this CPU can run, best last (gbviewer._native.simd_paths())."""
    return [str(p) for p in _native().simd_paths()]


def current_simd() -> str:
    """The path the CPU backend renders with now: GBVIEWER_SIMD when the module loaded, else the best, until
    set_simd (gbviewer._native.simd())."""
    return str(_native().simd())


def set_simd(path: str) -> None:
    """Switch the CPU backend's path for later renders in this process (gbviewer._native.testing.set_simd)."""
    _native().testing.set_simd(path)


def parse_simd(text: str | None) -> list[str]:
    """`--simd`: comma-separated paths, `all` (every path this CPU runs) or `current` (the one in use); None, the
    default, is scalar and the path in use. Returned in simd_paths() order (scalar first, best last); a path this
    CPU cannot run is an error."""
    avail, cur = simd_paths(), current_simd()
    if text is None:
        wanted = ["scalar", cur]
    else:
        wanted = []
        for name in (t.strip().lower() for t in text.split(",")):
            if name == "all":
                wanted += avail
            elif name == "current":
                wanted.append(cur)
            elif name:
                wanted.append(name)
    if not wanted:
        raise GBViewerError("--simd: no SIMD path given")
    unknown = [w for w in wanted if w not in SIMD_NAMES]
    if unknown:
        raise GBViewerError(
            f"--simd: unknown SIMD path(s) {unknown}; expected some of {', '.join(SIMD_NAMES)}, all or current"
        )
    missing = [w for w in wanted if w not in avail]
    if missing:
        raise GBViewerError(f"--simd: this CPU cannot run {', '.join(missing)} (it runs {', '.join(avail)})")
    return sorted(dict.fromkeys(wanted), key=avail.index)


def exp_rates(paths: list[str] | None = None, n: int = EXP_RATE_N, tries: int = 3) -> dict[str, float]:
    """exp evaluations per second on one core for each SIMD path (gbviewer._native.testing.exp_rate(path, n); the
    best of `tries`): the limit the blend's evaluation rate per core is measured against."""
    return {p: max(float(_native().testing.exp_rate(p, n)) for _ in range(tries)) for p in (paths or simd_paths())}


def simd_info(measured: list[str]) -> dict:
    """The CPU backend's SIMD paths: those this CPU runs, the one in use, GBVIEWER_SIMD, the ones measured, and the
    exp throughput of each path (per second, one core)."""
    return {
        "paths": simd_paths(),
        "in_use": current_simd(),
        "env": os.environ.get("GBVIEWER_SIMD"),
        "measured": list(measured),
        "exp_per_s_per_core": exp_rates(),
    }


def simd_summary(info: dict) -> str:
    """One line: 'SIMD scalar, avx2 (in use avx2; GBVIEWER_SIMD unset); exp per core: scalar 90M/s, avx2 400M/s'."""
    exp = ", ".join(f"{p} {v / 1e6:.0f}M/s" for p, v in info["exp_per_s_per_core"].items())
    env = info["env"] if info["env"] else "unset"
    return (
        f"SIMD paths {', '.join(info['paths'])} (in use {info['in_use']}; GBVIEWER_SIMD {env}; measuring "
        f"{', '.join(info['measured'])}); exp per core: {exp}"
    )
