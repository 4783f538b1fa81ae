"""The render mode a scene was trained with, from what its file says: `scene.meta["trained_as"]` and where it came
from (`trained_as_source`, e.g. "antialiased: spz flag"), and `trained_as_conflict` when signals disagree.

Signals, each a convention some trainer writes:
- PLY header `comment SplatRenderMode: mip|default` (Brush's exporter and reader; the same convention in gsplat
  PR #1036 and nerfstudio PR #3773): mip = gsplat's `antialiased` rasterize mode, default = `classic` 3DGS; a glTF
  file's `asset.extras` {"SplatRenderMode": ...}, gbviewer's own use of that convention where glTF has no field;
- the `.spz` header's antialiased flag (flags bit 0, Niantic's spz) and the SOG meta.json `antialias` field: set
  means antialiased, clear or absent says nothing (writers that do not know leave it clear);
- a `filter_3D` column: Mip-Splatting's 3D filter is in the data (it trains with its 2D mip filter as well).

Rule for conflicts (stated and reported, never silent): the data outranks a declaration (a `filter_3D` column wins
over a comment or flag that says otherwise), and among declarations the last one in the file wins (as Brush's and
splat-transform's readers do); every signal that lost is named in `trained_as_conflict`."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

THREEDGS = "3dgs"
ANTIALIASED = "antialiased"
MIP_3D = "mip-splatting (3D filter)"
UNKNOWN = "unknown"
TRAINED_AS = (THREEDGS, ANTIALIASED, MIP_3D, UNKNOWN)

COMMENT_KEY = "SplatRenderMode"
COMMENT_VALUES = {"mip": ANTIALIASED, "default": THREEDGS}  # what the comment's value means
WRITTEN = {ANTIALIASED: "mip", MIP_3D: "mip", THREEDGS: "default"}  # what `convert` writes for a training mode
_COMMENT = re.compile(rf"\s*{COMMENT_KEY}\s*:\s*(\S+)\s*", re.IGNORECASE)
HEADER_MAX_BYTES = 1 << 20


@dataclass(frozen=True)
class Signal:
    """One thing a file says about its training mode: the mode and where it was read."""

    value: str
    source: str

    @property
    def text(self) -> str:
        return f"{self.value}: {self.source}"


def ply_comments(path: Path) -> list[str]:
    """The `comment` lines of a PLY header, in order, without the keyword (empty for a file that is no PLY)."""
    with open(path, "rb") as fh:
        head = fh.read(HEADER_MAX_BYTES)
    if not head.startswith(b"ply"):
        return []
    end = head.find(b"end_header")
    lines = head[: end if end >= 0 else len(head)].decode("latin-1").splitlines()
    return [
        line.split(None, 1)[1] if len(line.split(None, 1)) > 1 else ""
        for line in lines
        if line.split(None, 1)[:1] == ["comment"]
    ]


def comment_signals(comments: list[str]) -> list[Signal]:
    """The SplatRenderMode comments among `comments`; an unknown value is an unknown mode, named as read."""
    out = []
    for c in comments:
        m = _COMMENT.fullmatch(c)
        if m:
            value = COMMENT_VALUES.get(m.group(1).lower(), UNKNOWN)
            out.append(Signal(value, f"PLY comment '{COMMENT_KEY}: {m.group(1)}'"))
    return out


def signals_of(meta: dict, comments: list[str] | None = None) -> list[Signal]:
    """Every training-mode signal of a loaded scene's `meta` (and its PLY header `comments`), data first."""
    out = [Signal(MIP_3D, "filter_3D column")] if meta.get("filter_3D") else []
    out += comment_signals(comments or [])
    declared = meta.get("splat_render_mode")
    if isinstance(declared, str):
        out.append(
            Signal(COMMENT_VALUES.get(declared.lower(), UNKNOWN), f"glTF asset.extras '{COMMENT_KEY}: {declared}'")
        )
    if meta.get("antialiased"):
        out.append(Signal(ANTIALIASED, "spz flag" if meta.get("format") == "spz" else "sog antialias field"))
    return out


def resolve(signals: list[Signal]) -> dict:
    """`trained_as`, `trained_as_source` and `trained_as_conflict` (None when the signals agree) under the module's
    rule: a filter_3D column wins; otherwise the last declaration does. An antialiased declaration agrees with a 3D
    filter (Mip-Splatting trains with its 2D filter too)."""
    if not signals:
        return {"trained_as": UNKNOWN, "trained_as_source": "the file does not say", "trained_as_conflict": None}
    data = [s for s in signals if s.source == "filter_3D column"]
    winner = data[0] if data else signals[-1]
    agrees = {winner.value, ANTIALIASED} if winner.value == MIP_3D else {winner.value}
    lost = [s for s in signals if s is not winner and s.value not in agrees]
    conflict = None
    if lost:
        rule = "the filter_3D column outranks a declaration" if data else "the last declaration wins"
        conflict = f"{'; '.join(s.text for s in lost)} overruled by {winner.text} ({rule})"
    return {"trained_as": winner.value, "trained_as_source": winner.source, "trained_as_conflict": conflict}


def describe(meta: dict) -> str:
    """'antialiased: spz flag', 'unknown: the file does not say', with ' (conflict: ...)' when there was one."""
    text = f"{meta.get('trained_as', UNKNOWN)}: {meta.get('trained_as_source', 'the file does not say')}"
    conflict = meta.get("trained_as_conflict")
    return text + (f" (conflict: {conflict})" if conflict else "")
