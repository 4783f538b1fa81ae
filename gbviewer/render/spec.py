"""What a mode spec text sets ('scalar:3', 'preset:spark+lod:40', ...): the parts `RenderSettings.parse` keeps, and
the texts its `spec` and messages write. Sits below types (whose Mode the spec's mode name becomes)."""

from __future__ import annotations

import enum
import re

from ..core.errors import RenderError
from .presets import PRESETS
from .view_filter import ViewFilter

PRECISIONS = ("exact", "fast")  # gaussian_blending's kernels (gbv/blend.h: blend_gaussian's Fast)


def spec_parts(spec: str) -> dict:
    """The RenderSettings fields a mode spec sets (see `RenderSettings.parse`), the mode as its name."""
    body, *suffixes = re.split(r"(?<![0-9][eE])\+", spec)  # not an exponent's sign ('+lod:1e+06')
    parts: dict = {}
    for suffix in suffixes:
        kind, _, tau = suffix.partition(":")
        kind = kind.strip().lower()
        key = "precision" if kind in PRECISIONS else kind
        if key not in ("lod", "precision") or key in parts or (kind in PRECISIONS and tau):
            raise RenderError(f"mode {spec!r}: expected MODE[:N][+fast|+exact][+lod[:TAU]]")
        parts[key] = (
            kind if kind in PRECISIONS else _spec_number(tau, float, spec, "LOD pixels") if tau.strip() else 1.0
        )
    name, _, n = body.strip().partition(":")
    name = name.strip().lower()
    if name == "preset":
        name, _, n = n.strip().partition(":")
        preset = PRESETS.get(name.strip().lower())
        if preset is None:
            raise RenderError(f"mode {spec!r}: unknown preset {name!r}; expected one of {', '.join(PRESETS)}")
        parts.update(mode=preset.mode, view_filter=preset.view_filter, preset=preset.name, sh_degree=preset.sh_degree)
    else:
        parts["mode"] = "scalar" if name == "supersample" else name  # RenderSettings parses (and checks) it
        if name == "stopthepop" and n.strip():  # 'stopthepop:K[:N]': K, its queue length, comes first
            queue, _, n = n.partition(":")
            parts["queue"] = _spec_number(queue, int, spec, "queue length")
    if n.strip():
        parts["supersample"] = _spec_number(n, int, spec, "supersampling factor")
    return parts


def _spec_number(text: str, kind: type, spec: str, what: str) -> float | int:
    try:
        return kind(text)
    except ValueError:
        raise RenderError(
            f"mode {spec!r}: {what} {text!r} is not {'an integer' if kind is int else 'a number'}"
        ) from None


def shortest(x: float) -> str:
    """A short text of `x` that reads back as it exactly ('40', '0.1', '12.3456789012', '1e06': no '+', which
    separates a spec's parts)."""
    text = f"{x:g}" if float(f"{x:g}") == x else repr(float(x))
    return text.replace("e+", "e")


def shown(value: object) -> str:
    """A field's value in a message: a mode's name, a view filter's parts, a number as written."""
    if isinstance(value, enum.Enum):
        return value.name.lower()
    return (
        value.describe() if isinstance(value, ViewFilter) else f"{value:g}" if isinstance(value, float) else str(value)
    )
