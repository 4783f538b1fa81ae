"""Every scene in ../shared/scenes loads with the documented count and SH degree; biker.spz agrees with
biker.compressed.ply within the two formats' quantisation."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import plyfile
import pytest
from helpers import IN_CI

import gbviewer as gb
from gbviewer.model.scene import SH_C0

SCENES = Path(__file__).resolve().parents[2].parent / "shared" / "scenes"
needs_scenes = pytest.mark.skipif(
    not SCENES.is_dir() and not IN_CI, reason=f"{SCENES} absent (shared/ is not beside the repo)"
)

# name: (format, version, splats, SH degree), from shared/scenes/SOURCES.md
EXPECTED = {
    "plant.splat": ("splat", None, 113_648, 0),
    "guitar.compressed.ply": ("compressed-ply", "18-property chunks", 90_854, 0),
    "biker.compressed.ply": ("compressed-ply", "18-property chunks", 152_746, 0),
    "biker.spz": ("spz", 4, 152_746, 0),
    "st-peter.sog": ("sog", 2, 133_618, 0),
    "angel.compressed.ply": ("compressed-ply", "12-property chunks", 71_377, 0),
    "v3dg-donut.fused.ply": ("inria-ply", None, 45_624, 0),
    "fruit_drops_minimal.ply": ("inria-ply", None, 4_721, 3),
}


def scene_files() -> list[str]:
    return sorted(p.name for p in SCENES.iterdir() if p.name != "SOURCES.md") if SCENES.is_dir() else []


@needs_scenes
def test_every_shared_scene_is_expected():
    assert set(scene_files()) == set(EXPECTED), "a scene was added or removed: update EXPECTED"


@needs_scenes
@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_shared_scene_loads(name):
    fmt, version, count, degree = EXPECTED[name]
    scene = gb.load(SCENES / name)
    assert (scene.meta["format"], scene.meta["version"]) == (fmt, version)
    assert scene.num_splats == count
    assert scene.sh_degree == degree
    assert np.isfinite(scene.means).all() and (scene.scales > 0).all()
    np.testing.assert_allclose(np.linalg.norm(scene.quats, axis=1), 1, atol=1e-6)


@needs_scenes
def test_biker_spz_matches_compressed_ply():
    """Same capture, same splat order. Per-value tolerance = sum of the two formats' half quantisation steps.

    spz: positions 24-bit fixed point with 12 fractional bits -> 2^-13; log scales step 1/16 -> 1/32, range
    [-10, 5.9375]; alpha 8 bits -> 0.5/255; colour step 1/(0.15*255) in DC units -> 0.5/(0.15*255); quaternion
    smallest-three, 9-bit magnitudes of at most 1/sqrt2 -> (1/sqrt2)/511/2.
    compressed ply: positions 11/10/11 bits of the chunk range -> range/(2*2047) (y: 1023); log scales the same;
    colour 8 bits of the chunk colour range -> range/(2*255) in colour, /SH_C0 in DC; alpha 0.5/255;
    quaternion 10 bits over [-1/sqrt2, 1/sqrt2] -> sqrt2/1023/2.
    """
    spz = gb.load(SCENES / "biker.spz")
    cply = gb.load(SCENES / "biker.compressed.ply")
    chunk = plyfile.PlyData.read(str(SCENES / "biker.compressed.ply"))["chunk"].data
    n = cply.num_splats

    def per_splat(prefix: str, axes) -> np.ndarray:
        rng = np.stack([chunk[f"max_{prefix}{a}"] - chunk[f"min_{prefix}{a}"] for a in axes], axis=1)
        return np.repeat(rng, 256, axis=0)[:n]

    bits = np.array([2047, 1023, 2047])
    pos_tol = 2.0**-13 + per_splat("", "xyz") / (2 * bits) + 1e-6
    assert (np.abs(spz.means - cply.means) <= pos_tol).all()

    log_c = np.log(cply.scales)
    inside = (log_c > -10 + 1 / 32) & (log_c < 5.9375 - 1 / 32)  # spz clamps log scales to its byte range
    scale_tol = 1 / 32 + per_splat("scale_", "xyz") / (2 * bits) + 1e-5
    assert (np.abs(np.log(spz.scales) - log_c) <= scale_tol)[inside].all()
    assert inside.mean() > 0.95
    assert (np.log(spz.scales)[log_c <= -10] <= -10 + 1 / 32 + 1e-5).all()

    assert np.abs(spz.opacities - cply.opacities).max() <= 1 / 255 + 1e-6
    dc_tol = 0.5 / (0.15 * 255) + per_splat("", "rgb") / (2 * 255 * SH_C0) + 1e-5
    assert (np.abs(spz.sh[:, 0] - cply.sh[:, 0]) <= dc_tol).all()

    # Component error: sum of both half steps for the three stored ones; the rebuilt largest (>= 1/2)
    # inherits at most sum(|q_i|) * e / q_max <= 3 * (1/sqrt2) * e / (1/2).
    e = (1 / math.sqrt(2)) / 511 / 2 + math.sqrt(2) / 1023 / 2
    sign = np.sign(np.einsum("ij,ij->i", spz.quats, cply.quats))[:, None]
    assert np.abs(spz.quats - sign * cply.quats).max() <= 3 * math.sqrt(0.5) * e / 0.5 + 1e-6
