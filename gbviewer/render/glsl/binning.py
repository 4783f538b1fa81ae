"""Tile lists of the glsl backend: the preprocessed splats binned by tile (and depth), or duplex's cells sorted by
depth, binned, and expanded into their splats. Each returns the list buffer and the tiles' [start, end) ranges in it."""

from __future__ import annotations

import numpy as np

from ...model.cells import Cells
from ..types import Mode
from . import interface as gi
from .gpu import WG, Gpu
from .sort import fill, pairs_by_tile, radix_sort, scan

WORD = gi.WORD_BYTES
RANGE_BYTES = gi.RANGE_WORDS * WORD


def read_totals(gpu: Gpu) -> np.ndarray:
    """The counter buffer (indexed by interface.TOTAL_*)."""
    return np.frombuffer(gpu.buffers["totals"].read(size=gi.TOTALS_BYTES), np.uint32).astype(np.int64)


def bin_splats(
    gpu: Gpu,
    mode: Mode,
    visible: int,
    pairs: int,
    dmin: int,
    dmax: int,
    num_tiles: int,
    gx: int,
    tile_depth_cam: tuple | None = None,
):
    """Tile lists of splats: by (tile, depth, index), or for wsr by (tile, index) with no depth sort; with
    `tile_depth_cam` (stopthepop:K, the render resolution's fx, fy, cx, cy) then by StopThePop's tile key."""
    dkeys = [gpu.buffers[f"depth_keys{i}"] for i in (0, 1)]
    dvals = [gpu.buffers[f"depth_vals{i}"] for i in (0, 1)]
    ranges = gpu.ensure("ranges", num_tiles * RANGE_BYTES, "tile ranges")
    fill(gpu, ranges, num_tiles * gi.RANGE_WORDS, 0)
    if visible == 0:
        return gpu.ensure("tile_vals0", pairs * WORD, "tile-splat pairs"), ranges
    if mode == Mode.WSR:
        order = dvals[0]  # survivors in splat-index order: binning only
    else:
        _, order = radix_sort(gpu, dkeys[0], dvals[0], dkeys[1], dvals[1], visible, (dmax - dmin).bit_length())
    tkeys, tvals = pairs_by_tile(
        gpu,
        order,
        gpu.buffers["rects"],
        gpu.buffers["pair_counts"],
        visible,
        pairs,
        gx,
        num_tiles,
        ranges,
        "tile-splat pairs",
    )
    if tile_depth_cam is not None and pairs > 0:
        tvals = tile_depth_resort(gpu, tkeys, tvals, pairs, num_tiles, gx, tile_depth_cam)
    return tvals, ranges


def tile_depth_resort(gpu: Gpu, tkeys, tvals, pairs: int, num_tiles: int, gx: int, cam_f: tuple):
    """stopthepop:K's tile stage (gbv/resort.h): every tile's list, in (centre depth, index) order, stably sorted by
    its splats' tile keys (tile_keys.comp): an LSD sort by the key, then by the tile. Returns the list buffer."""
    dk = [gpu.ensure(f"pair_depth_keys{i}", pairs * WORD, "tile depth keys") for i in (0, 1)]
    pos = [gpu.ensure(f"pair_positions{i}", pairs * WORD, "tile depth order") for i in (0, 1)]
    gpu.run(
        "tile_keys.comp",
        -(-pairs // WG),
        (gpu.buffers["splats"], gpu.buffers["rays"], tkeys, tvals, dk[0], pos[0]),
        n=pairs,
        grid_x=gx,
        cam_f=cam_f,
    )
    _, order = radix_sort(gpu, dk[0], pos[0], dk[1], pos[1], pairs, 32)
    gpu.run("gather_pairs.comp", -(-pairs // WG), (order, tkeys, tvals, dk[0], dk[1]), n=pairs)
    _, out = radix_sort(gpu, dk[0], dk[1], tkeys, tvals, pairs, (num_tiles - 1).bit_length())
    return out


def bin_duplex(gpu: Gpu, cells: Cells, cam_uniforms: dict, num_tiles: int):
    """Duplex binning (docs/modes.md#duplex): project the cells with a visible splat, sort them by depth, one pair per
    (tile, cell), sort the pairs by tile, expand every pair to its cell's visible splats. Returns the splat list,
    the tile ranges in it, the tile-cell pairs (the sort length), the list length and the visible cells."""
    m = cells.num_cells
    gx = cam_uniforms["grid"][0]
    totals, cell_offsets = gpu.buffers["totals"], gpu.buffers["cell_offsets"]
    cell_out = gpu.ensure("cell_out", m * gi.CELL_OUT_VEC4S * gi.VEC4_BYTES, "projected cells")
    cell_rects = gpu.ensure("cell_rects", m * gi.RECT_WORDS * WORD, "cell rectangles")
    cflags = gpu.ensure("cell_flags", m * WORD, "cell flags")
    vis = gpu.ensure("cell_vis", len(cells.members) * WORD, "visible cell members")
    gpu.run(
        "cells.comp",
        -(-m // WG),
        (
            gpu.buffers["cell_geom"],
            cell_offsets,
            gpu.buffers["cell_members"],
            gpu.buffers["rects"],
            vis,
            cell_out,
            cell_rects,
            cflags,
            totals,
        ),
        num_cells=m,
        **cam_uniforms,
    )
    scan(gpu, cflags, m, total_slot=gi.TOTAL_CELLS)
    t = read_totals(gpu)
    cell_pairs, cmin, cmax, ncells = (
        int(t[i]) for i in (gi.TOTAL_CELL_PAIRS, gi.TOTAL_CELL_DEPTH_MIN, gi.TOTAL_CELL_DEPTH_MAX, gi.TOTAL_CELLS)
    )
    ckeys = [gpu.ensure(f"cell_keys{i}", m * WORD, "cell keys") for i in (0, 1)]
    cvals = [gpu.ensure(f"cell_vals{i}", m * WORD, "cell order") for i in (0, 1)]
    gpu.run("cell_compact.comp", -(-m // WG), (cell_out, cell_rects, cflags, totals, ckeys[0], cvals[0]), num_cells=m)
    cell_ranges = gpu.ensure("cell_ranges", num_tiles * RANGE_BYTES, "tile ranges of cells")
    ranges = gpu.ensure("ranges", num_tiles * RANGE_BYTES, "tile ranges")
    fill(gpu, ranges, num_tiles * gi.RANGE_WORDS, 0)
    fill(gpu, cell_ranges, num_tiles * gi.RANGE_WORDS, 0)
    expanded = 0
    tlist = gpu.ensure("expanded", WORD)
    if ncells > 0 and cell_pairs > 0:
        _, order = radix_sort(gpu, ckeys[0], cvals[0], ckeys[1], cvals[1], ncells, (cmax - cmin).bit_length())
        counts = gpu.ensure("cell_pair_counts", ncells * WORD, "cell tile counts")
        _, tvals = pairs_by_tile(
            gpu, order, cell_rects, counts, ncells, cell_pairs, gx, num_tiles, cell_ranges, "tile-cell pairs"
        )
        offs = gpu.ensure("expand_offsets", cell_pairs * WORD, "expanded list offsets")
        groups = -(-cell_pairs // WG)
        gpu.run("expand.comp", groups, (tvals, cell_out, cell_offsets, vis, offs, tlist), n=cell_pairs, mode=0)
        scan(gpu, offs, cell_pairs, total_slot=gi.TOTAL_EXPANDED)
        expanded = int(read_totals(gpu)[gi.TOTAL_EXPANDED])
        tlist = gpu.ensure("expanded", expanded * WORD, "expanded tile lists")
        gpu.run("expand.comp", groups, (tvals, cell_out, cell_offsets, vis, offs, tlist), n=cell_pairs, mode=1)
        gpu.run(
            "expand_ranges.comp",
            -(-num_tiles // WG),
            (cell_ranges, offs, totals, ranges),
            num_tiles=num_tiles,
            n=cell_pairs,
        )
    return tlist, ranges, cell_pairs, expanded, ncells
