"""GPU prefix sums, the stable radix sort and tile binning of the glsl backend (shaders/scan_*, radix_*,
gather_counts, duplicate, tile_ranges, fill)."""

from __future__ import annotations

from . import interface as gi
from .gpu import WG, Gpu

SCAN_BLOCK = 1024  # elements per scan_blocks group
RADIX_BLOCK = 2048  # keys per radix group (256 threads x 8)
RADIX_BITS = 4


def scan(gpu: Gpu, buf, n: int, total_slot: int = gi.NO_TOTAL, level: int = 0) -> None:
    """Exclusive prefix sum of uint buf[0..n) in place; the total goes to counter slot `total_slot` (interface.TOTAL_*)
    unless it is NO_TOTAL."""
    if n <= 0:
        return
    blocks = -(-n // SCAN_BLOCK)
    sums = gpu.ensure(f"scan_sums{level}", blocks * gi.WORD_BYTES)
    gpu.run(
        "scan_blocks.comp",
        blocks,
        (buf, sums, gpu.ensure("totals", gi.TOTALS_BYTES)),
        n=n,
        num_blocks=blocks,
        total_slot=total_slot,
    )
    if blocks > 1:
        scan(gpu, sums, blocks, total_slot, level + 1)
        gpu.run("scan_add.comp", blocks, (buf, sums), n=n, num_blocks=blocks)


def radix_sort(gpu: Gpu, keys, vals, keys_tmp, vals_tmp, n: int, bits: int):
    """Stable LSD sort of (keys, vals)[0..n) by the low `bits` of the keys; returns the buffers holding it."""
    passes = -(-bits // RADIX_BITS)
    if n <= 1 or passes == 0:
        return keys, vals
    blocks = -(-n // RADIX_BLOCK)
    counts = gpu.ensure("radix_counts", (1 << RADIX_BITS) * blocks * gi.WORD_BYTES)
    for p in range(passes):
        shift = p * RADIX_BITS
        gpu.run("radix_count.comp", blocks, (keys, counts), n=n, shift=shift, num_blocks=blocks)
        scan(gpu, counts, (1 << RADIX_BITS) * blocks)
        gpu.run(
            "radix_scatter.comp", blocks, (keys, vals, keys_tmp, vals_tmp, counts), n=n, shift=shift, num_blocks=blocks
        )
        keys, vals, keys_tmp, vals_tmp = keys_tmp, vals_tmp, keys, vals
    return keys, vals


def fill(gpu: Gpu, buf, n: int, value: int) -> None:
    """buf[0..n) = value (uint)."""
    gpu.run("fill.comp", -(-n // WG), (buf,), n=n, value=value)


def pairs_by_tile(gpu: Gpu, order, rects, counts, n: int, pairs: int, gx: int, num_tiles: int, ranges, what: str):
    """One (tile, item) pair for every tile each of the n ordered items touches (`rects`), stably radix-sorted by
    tile, so every tile keeps the items' order; writes each tile's [start, end) into `ranges` and returns the pairs'
    tiles and items in tile order."""
    keys0, vals0, keys1, vals1 = (
        gpu.ensure(f"tile_{k}{i}", pairs * gi.WORD_BYTES, what) for i in (0, 1) for k in ("keys", "vals")
    )
    gpu.run("gather_counts.comp", -(-n // WG), (order, rects, counts), n=n)
    scan(gpu, counts, n)
    gpu.run(
        "duplicate.comp",
        -(-pairs // WG),
        (order, rects, counts, keys0, vals0),
        num_pairs=pairs,
        num_splats=n,
        grid_x=gx,
    )
    tkeys, tvals = radix_sort(gpu, keys0, vals0, keys1, vals1, pairs, (num_tiles - 1).bit_length())
    gpu.run("tile_ranges.comp", -(-pairs // WG), (tkeys, ranges), n=pairs)
    return tkeys, tvals
