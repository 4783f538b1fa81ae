"""INRIA 3DGS `.ply` (docs/formats.md#inria-3dgs-ply): raw parameters per vertex, activated on load.

Also the sort-free GS layout (docs/formats.md#variant-layouts): the INRIA columns plus `f_do_0`, `f_ro_*` (the view
weight v_i as a raw 1-channel SH, kept as `Scene.oit.view_weight_sh`) and `info`, a column that carries the globals in
its first rows: info[0] = weight_background, info[1] = sigma."""

from __future__ import annotations

import importlib
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import plyfile

from ..core.errors import GBViewerError, SceneFormatError
from ..model.scene import MAX_SCALE, MAX_SH, Checked, Scene
from . import progress as load_progress
from .ply_read import column_table
from .progress import LoadProgress

REQUIRED = [
    "x",
    "y",
    "z",
    "f_dc_0",
    "f_dc_1",
    "f_dc_2",
    "opacity",
    "scale_0",
    "scale_1",
    "scale_2",
    "rot_0",
    "rot_1",
    "rot_2",
    "rot_3",
]
REST_COUNTS = {0: 0, 9: 1, 24: 2, 45: 3}  # f_rest_* count -> SH degree
REST_COUNTS_1 = {0: 0, 3: 1, 8: 2, 15: 3}  # f_ro_* count (1-channel view weight) -> SH degree


def check_sh_range(sh: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """`sh`, once checked to fit `dtype` (`check_sh_magnitude`)."""
    if np.dtype(dtype) == np.float16 and sh.size:
        check_sh_magnitude(max(float(np.fmax.reduce(sh, axis=None)), -float(np.fmin.reduce(sh, axis=None))), dtype)
    return sh


def check_sh_magnitude(big: float, dtype: np.dtype) -> None:
    """float16 storage (`gb.load(..., sh_dtype="float16")`) refuses SH coefficients up to `big` in magnitude when that
    is beyond its largest finite value, rather than turning them into infinities."""
    if np.dtype(dtype) == np.float16 and big > float(np.finfo(np.float16).max):
        raise GBViewerError(
            f"field 'sh': coefficients up to {big:.3g}, beyond float16's range (65504); load with sh_dtype='float32'"
        )


def native_io():
    """`gbviewer._native.io` (the INRIA row scatter), or a GBViewerError saying why the native module does not
    import (a GBVIEWER_SIMD the CPU lacks, say): imported here, not with gbviewer, which imports without it. By
    name: the compiled module is a leaf that imports nothing of gbviewer, but the import linter, which sees only
    .py files, would take `from .. import _native` for an import of the whole package (and so of render)."""
    try:
        return importlib.import_module("gbviewer._native").io
    except ImportError as exc:
        raise GBViewerError(
            f"the native module gbviewer._native does not import ({exc}); the .ply loader needs it"
        ) from None


def activate_opacity(raw: np.ndarray) -> np.ndarray:
    """sigmoid in float32 (the writer inverts exactly this)."""
    with np.errstate(over="ignore"):
        return 1.0 / (1.0 + np.exp(-raw))


def activate_scales(raw: np.ndarray) -> np.ndarray:
    """exp in float32 (the writer inverts exactly this)."""
    with np.errstate(over="ignore"):
        return np.exp(raw)


@dataclass(frozen=True)
class InriaLayout:
    """What an INRIA vertex table holds (checked by `inria_layout`): its properties, SH degree and f_rest columns, a
    filter_3D column, and for the sort-free layout its view-weight columns (f_do_0, f_ro_*) and `info`."""

    names: list[str]
    degree: int
    rest: list[str]
    has_filter: bool
    weight_cols: list[str]

    @property
    def wanted(self) -> list[str]:
        return REQUIRED + self.rest + (["filter_3D"] if self.has_filter else []) + self.weight_cols


def inria_layout(path: Path, names: list[str], n: int) -> InriaLayout:
    """The layout of an `n`-row INRIA vertex table with properties `names`, or a SceneFormatError saying what is
    wrong with it (no rows, f_rest_* or f_ro_* counts, a sort-free table without `info`)."""
    if n == 0:
        raise SceneFormatError(path, "zero splats", field="vertex")
    rest_idx = sorted(int(m.group(1)) for n in names if (m := re.fullmatch(r"f_rest_(\d+)", n)))
    if len(rest_idx) not in REST_COUNTS or rest_idx != list(range(len(rest_idx))):
        raise SceneFormatError(
            path,
            f"{len(rest_idx)} f_rest_* properties (indices {rest_idx[:3]}...); expected f_rest_0.. with "
            "0, 9, 24 or 45 of them (SH degree 0-3)",
            field="f_rest",
        )
    ro_idx = sorted(int(m.group(1)) for n in names if (m := re.fullmatch(r"f_ro_(\d+)", n)))
    weight_cols: list[str] = []
    if "f_do_0" in names or ro_idx:
        if "f_do_0" not in names or len(ro_idx) not in REST_COUNTS_1 or ro_idx != list(range(len(ro_idx))):
            raise SceneFormatError(
                path,
                f"sort-free view weight: f_do_0 {'present' if 'f_do_0' in names else 'missing'} and "
                f"{len(ro_idx)} f_ro_* properties; expected f_do_0 and f_ro_0.. with 0, 3, 8 or 15 of them",
                field="f_ro",
            )
        if "info" not in names:
            raise SceneFormatError(
                path,
                "sort-free layout (f_do_0) without the 'info' column that holds weight_background and sigma",
                field="info",
            )
        weight_cols = ["f_do_0"] + [f"f_ro_{i}" for i in ro_idx] + ["info"]
    return InriaLayout(
        names, REST_COUNTS[len(rest_idx)], [f"f_rest_{i}" for i in rest_idx], "filter_3D" in names, weight_cols
    )


class InriaArrays:
    """The Scene's final arrays of an INRIA load, allocated once: `fill` copies raw columns into them a row range
    at a time (no array of the whole file besides them), `activate` applies exp and sigmoid in place."""

    def __init__(self, layout: InriaLayout, n: int, sh_dtype: str = "float32") -> None:
        self.layout, self.n, k = layout, n, (layout.degree + 1) ** 2
        self.means, self.scales = np.empty((n, 3), np.float32), np.empty((n, 3), np.float32)
        self.quats, self.opacities = np.empty((n, 4), np.float32), np.empty(n, np.float32)
        self.sh = np.empty((n, k, 3), sh_dtype)
        self.filter_3d = np.empty(n, np.float32) if layout.has_filter else None
        self.weights = np.empty((n, len(layout.weight_cols) - 1), np.float32) if layout.weight_cols else None
        self.info = np.zeros(min(n, 2), np.float32)
        self.keep = np.empty(n, bool)
        self._scatter = native_io().scatter_inria

    def fill(self, table: np.ndarray, cols: np.ndarray, rows: slice, threads: int = 0) -> tuple[float, float]:
        """Scatter `table` (rows, C) float32, the raw rows `rows`, its columns at `cols` (`column_table` of
        `layout.wanted`) into the arrays: copied, checked and normalised as Scene.from_arrays would
        (`gbviewer._native.io.scatter_inria` on `threads` threads, 0: all; `keep` marks the splats it would keep).
        Calls for different rows may run at once. Returns the rows' largest |f_dc| and |f_rest| for `check_sh`."""
        sliced = [None if a is None else a[rows] for a in (self.filter_3d, self.weights)]
        maxima = self._scatter(
            table,
            cols[:-1] if self.weights is not None else cols,
            self.means[rows],
            self.scales[rows],
            self.quats[rows],
            self.opacities[rows],
            self.sh[rows],
            *sliced,
            self.keep.view(np.uint8)[rows],
            MAX_SH,
            threads,
        )
        if self.weights is not None and rows.start < len(self.info):
            head = table[: len(self.info) - rows.start, cols[-1]]
            self.info[rows.start : rows.start + len(head)] = head
        return maxima

    def check_sh(self, dc: float, rest: float) -> None:
        """Refuse SH coefficients as large as `fill` found (the DC block's first) when the storage cannot hold them."""
        check_sh_magnitude(dc, self.sh.dtype)
        check_sh_magnitude(rest, self.sh.dtype)

    def activate(self, rows: slice) -> None:
        """exp of the scales, sigmoid of the opacities of rows `rows`, in place; `keep` then also drops the splats
        whose activated scale is beyond MAX_SCALE (or not finite) and whose opacity is NaN, as Scene.from_arrays."""
        scales, opacities = self.scales[rows], self.opacities[rows]
        scales[...] = activate_scales(scales)
        opacities[...] = activate_opacity(opacities)
        ok = scales <= np.float32(MAX_SCALE)
        if not ok.all():  # the per-splat reduction only where a chunk has such a scale
            self.keep[rows] &= ok.all(axis=1)
        self.keep[rows] &= ~np.isnan(opacities)

    def scene(self, path: Path) -> Scene:
        """The validated Scene of the filled, activated arrays."""
        layout, n = self.layout, self.n
        meta = {
            "format": "inria-ply",
            "version": None,
            "properties": layout.names,
            "sh_degree": layout.degree,
            "filter_3D": layout.has_filter,
        }
        extra: dict = {}
        if self.weights is not None:
            if n < 2:
                raise SceneFormatError(
                    path,
                    f"sort-free layout with {n} vertex; the info column needs 2 rows (weight_background, sigma)",
                    field="info",
                )
            wbg, sigma = float(self.info[0]), float(self.info[1])
            if not (np.isfinite(wbg) and wbg >= 0 and np.isfinite(sigma) and sigma > 0):
                raise SceneFormatError(
                    path,
                    f"info rows 0, 1 (weight_background, sigma) = {wbg}, {sigma}; expected "
                    "weight_background >= 0 and sigma > 0",
                    field="info",
                )
            extra = {"weight_background": wbg, "wsr_sigma": sigma, "view_weight_sh": self.weights}
            meta.update(format="sort-free-ply", sort_free=True)
        return Scene.from_arrays(
            self.means,
            self.scales,
            self.quats,
            self.opacities,
            self.sh,
            self.filter_3d,
            source=str(path),
            meta=meta,
            checked=Checked(self.keep),
            **extra,
        )


def load_inria_ply(path: Path, ply: plyfile.PlyData, progress: LoadProgress | None = None) -> Scene:
    """Load an INRIA-layout splat PLY read by `read_ply` (ASCII, or binary that `load_streamed_ply` leaves): exp
    scales, sigmoid opacity, normalised (w,x,y,z) quaternions. `progress`: splats decoded."""
    if "vertex" not in ply:
        raise SceneFormatError(path, "no 'vertex' element", field="vertex")
    n = ply["vertex"].count
    layout = inria_layout(path, list(ply["vertex"].data.dtype.names or ()), n)
    table, cols = column_table(path, ply["vertex"].data, layout.wanted)
    out = InriaArrays(layout, n)
    for begin, end in (progress or LoadProgress()).chunks(n, "splats", load_progress.MIN_SPLATS):
        rows = slice(begin, end)
        out.check_sh(*out.fill(table[rows], cols, rows))
        out.activate(rows)
    return out.scene(path)
