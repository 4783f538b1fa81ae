"""The streamed INRIA `.ply` loader (`gbviewer.io.ply_stream.load_streamed_ply`): the same arrays, bit for bit, as an
independent whole-file decode with plyfile and as the memory-mapped path (`read_ply` + `load_inria_ply`), on every
vertex layout, the fuzz seeds and the shared scenes, in one chunk or a hundred."""

from __future__ import annotations

import os
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import plyfile
import pytest
from helpers import shared_scene

import gbviewer as gb
from gbviewer.io import ply_stream
from gbviewer.io import progress as load_progress
from gbviewer.io.ply import check_sh_range, load_inria_ply
from gbviewer.io.ply_read import read_ply
from gbviewer.io.ply_stream import load_streamed_ply
from gbviewer.io.write import ply_header

SEEDS = Path(__file__).parent / "fuzz" / "seeds"
BASE = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
TAIL = ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]


def raw_ply(
    path: Path,
    n: int,
    degree: int = 3,
    seed: int = 0,
    extra: tuple = (),
    dtypes: dict | None = None,
    byte_order: str = "<",
    shuffle: bool = False,
    sort_free: int | None = None,
    faces: int = 0,
    extremes: np.ndarray | None = None,
) -> Path:
    """An INRIA vertex table of random raw values: SH `degree`, `extra` columns (filter_3D, ...), `dtypes` per
    column (default float32), shuffled columns, the sort-free columns of view-weight degree `sort_free`, and
    `faces` mesh faces after the vertices. `extremes`: values planted in 2% of each float column's rows, and
    the rows of QUATS planted as quaternions."""
    rng = np.random.default_rng(seed)
    names = BASE + [f"f_rest_{i}" for i in range(3 * ((degree + 1) ** 2 - 1))] + TAIL + list(extra)
    if sort_free is not None:
        names += ["f_do_0"] + [f"f_ro_{i}" for i in range((sort_free + 1) ** 2 - 1)] + ["info"]
    if shuffle:
        names = list(rng.permutation(names))
    dtypes = dtypes or {}
    dt = np.dtype([(nm, byte_order + dtypes.get(nm, "f4")) for nm in names])
    data = np.empty(n, dt)
    for nm in names:
        data[nm] = rng.normal(0, 2, n) if not nm.startswith("rot") else rng.normal(0, 1, n)
    if extremes is not None:
        for nm in names:
            if data[nm].dtype.kind == "f" and nm != "info":
                rows = rng.random(n) < 0.02
                data[nm][rows] = rng.choice(extremes, rows.sum())
        rows = rng.choice(n, min(n, 3 * len(QUATS)), replace=False)
        for i, q in zip(rows, np.resize(QUATS, (len(rows), 4))):
            for c in range(4):
                data[f"rot_{c}"][i] = q[c]
    if sort_free is not None:
        data["info"][:2] = (0.05, 8.0)
    elements = [plyfile.PlyElement.describe(data, "vertex")]
    if faces:
        tri = np.empty(faces, [("vertex_indices", "i4", (3,))])
        tri["vertex_indices"] = rng.integers(0, n, (faces, 3))
        elements.append(plyfile.PlyElement.describe(tri, "face"))
    plyfile.PlyData(elements, byte_order=byte_order).write(str(path))
    return path


def reference(path: Path) -> gb.Scene:
    """An independent decode: plyfile reads the whole file into memory, INRIA activations in one go."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return decode(path)


def decode(path: Path) -> gb.Scene:
    """`reference`, its warnings left to the caller."""
    v = plyfile.PlyData.read(str(path), mmap=False)["vertex"].data
    names = v.dtype.names
    col = lambda *cols: np.stack([np.asarray(v[c], np.float32) for c in cols], axis=1)  # noqa: E731
    rest = sorted((c for c in names if c.startswith("f_rest_")), key=lambda c: int(c[7:]))
    k = len(rest) // 3 + 1
    sh = np.empty((len(v), k, 3), np.float32)
    sh[:, 0] = col("f_dc_0", "f_dc_1", "f_dc_2")
    if rest:
        sh[:, 1:] = col(*rest).reshape(-1, 3, k - 1).transpose(0, 2, 1)
    with np.errstate(over="ignore"):
        scales = np.exp(col("scale_0", "scale_1", "scale_2"))
        opac = 1.0 / (1.0 + np.exp(-col("opacity")[:, 0]))
    extra = {}
    if "f_do_0" in names:
        ro = sorted((c for c in names if c.startswith("f_ro_")), key=lambda c: int(c[5:]))
        info = np.asarray(v["info"], np.float32)
        extra = {"view_weight_sh": col("f_do_0", *ro), "weight_background": float(info[0]), "wsr_sigma": float(info[1])}
    filt = col("filter_3D")[:, 0] if "filter_3D" in names else None
    return gb.Scene.from_arrays(
        col("x", "y", "z"), scales, col("rot_0", "rot_1", "rot_2", "rot_3"), opac, sh, filt, source=str(path), **extra
    )


def arrays(scene: gb.Scene) -> dict[str, np.ndarray | None]:
    out = {n: getattr(scene, n) for n in ("means", "scales", "quats", "opacities", "sh", "filter_3d")}
    out["view_weight_sh"] = scene.oit.view_weight_sh if scene.oit is not None else None
    return out


def assert_same(a: gb.Scene, b: gb.Scene) -> None:
    for (name, x), y in zip(arrays(a).items(), arrays(b).values()):
        assert (x is None) == (y is None), name
        if x is not None:
            half = name == "sh" and x.dtype == np.float16  # sh_dtype="float16"
            assert x.dtype == y.dtype == (np.float16 if half else np.float32) and x.flags.c_contiguous, name
            np.testing.assert_array_equal(x, y, err_msg=name, strict=True)
    if a.oit is not None:
        assert (a.oit.sigma, a.oit.weight_background) == (b.oit.sigma, b.oit.weight_background)


def mapped(path: Path) -> gb.Scene:
    """Today's memory-mapped path, which ASCII files and other layouts still take."""
    return load_inria_ply(path, read_ply(path))


def load_quietly(path: Path) -> gb.Scene:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # random raw values: a few overflow and are dropped, on every path alike
        return gb.load(path)


# Values at the edges of Scene.from_arrays's checks: non-finite, the SH limit 1e30 and the next float32, a raw scale
# either side of log(MAX_SCALE) = 41.4465 and of exp's overflow, opacities whose sigmoid is 0 or 1, float16's range.
EDGES = np.array(
    [
        np.nan,
        np.inf,
        -np.inf,
        1e30,
        np.nextafter(np.float32(1e30), np.float32(np.inf)),
        -1e30,
        -3e38,
        0.0,
        -0.0,
        1e-30,
        41.4465,
        41.4466,
        88.72,
        89.0,
        -104.0,
        65504.0,
        -65504.0,
        1.00048828125,
    ],
    np.float32,
)
HALF_EDGES = np.array(
    [np.nan, 65504.0, -65504.0, 0.0, -0.0, 1e-8, 2.98e-8, 6e-8, 3e-5, 1.00048828125, 41.4466, 89.0, -104.0], np.float32
)  # all within float16's range (NaN: a dropped splat)
# Quaternions at the edges of the normalisation: squares that overflow, norms under 1e-12, within and just beyond
# 4 float32 eps of unit length, zero, non-finite.
QUATS = np.array(
    [
        [3e38, 3e38, 3e38, 3e38],
        [-3e38, 1.0, 0.0, 0.0],
        [1e-13, 0, 0, 0],
        [0, 0, 0, 0],
        [1, 0, 0, 0],
        [1 + 2**-22, 0, 0, 0],
        [1 + 2**-20, 0, 0, 0],
        [0.5, 0.5, 0.5, 0.5],
        [1e-20, 1e-20, 0, 0],
        [np.inf, 0, 0, 1],
        [np.nan, 1, 0, 0],
        [1e-7, 1e-7, 1e-7, 1.0],
    ],
    np.float32,
)

LAYOUTS = {
    "sh3": {},
    "sh0": {"degree": 0},
    "sh1": {"degree": 1},
    "sh2": {"degree": 2},
    "filter": {"extra": ("filter_3D",)},
    "shuffled": {"shuffle": True, "extra": ("filter_3D",)},
    "big-endian": {"byte_order": ">"},
    "mixed-types": {"dtypes": {"x": "f8", "nx": "u1", "scale_1": "f8", "f_rest_4": "i2", "opacity": "f8"}},
    "sort-free": {"sort_free": 2},
    "sort-free-sh0": {"sort_free": 0, "degree": 1},
    "faces-after": {"faces": 50},
}


@pytest.fixture(params=[0, 1, 2], ids=["default-chunks", "tiny-chunks", "tiny-blocks"])
def chunks(request, monkeypatch):
    if request.param:  # a chunk per hundredth of the file: many row ranges, one of them possibly a single row
        monkeypatch.setattr(load_progress, "MIN_BYTES", 1)
        monkeypatch.setattr(load_progress, "MIN_SPLATS", 1)
        monkeypatch.setattr(os, "cpu_count", lambda: 3)  # several workers whatever the machine
    if request.param == 2:  # each worker reads and scatters its range a few rows at a time (the last block shorter)
        monkeypatch.setattr(ply_stream, "SCATTER_BYTES", 1000)
    return request.param


@pytest.mark.parametrize(
    "layout, n", [(lay, n) for lay in LAYOUTS for n in (1, 2, 7, 3001) if n > 1 or "sort_free" not in LAYOUTS[lay]]
)  # sort-free needs 2 rows
def test_streamed_equals_reference_and_mapped_path(tmp_path, layout, n, chunks):
    path = raw_ply(tmp_path / "s.ply", n, seed=n, **LAYOUTS[layout])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        streamed = load_streamed_ply(path)
        assert streamed is not None  # every binary vertex-first table is streamed
        assert_same(streamed, reference(path))
        assert_same(streamed, mapped(path))
        assert_same(load_quietly(path), streamed)
    assert streamed.meta["properties"] == list(plyfile.PlyData.read(str(path))["vertex"].data.dtype.names)


@pytest.mark.parametrize("seed", sorted(p.name for p in (SEEDS / "inria").iterdir()))
def test_fuzz_seeds_load_as_before(seed, chunks):
    path = SEEDS / "inria" / seed
    scene = gb.load(path)
    assert_same(scene, reference(path))
    assert_same(scene, mapped(path))
    assert (load_streamed_ply(path) is None) == (seed == "ascii.ply")  # ASCII: the row-by-row path


def test_without_preadv_the_workers_read_the_file_under_a_lock(tmp_path, monkeypatch):
    """Where os.preadv is missing (Windows), the workers seek and read the one open file in turn: the same arrays."""
    path = raw_ply(tmp_path / "s.ply", 3001, seed=4, extra=("filter_3D",))
    monkeypatch.setattr(load_progress, "MIN_BYTES", 1)
    monkeypatch.setattr(ply_stream, "SCATTER_BYTES", 1000)
    monkeypatch.setattr(os, "cpu_count", lambda: 3)
    monkeypatch.delattr(os, "preadv", raising=False)
    assert_same(load_quietly(path), reference(path))


def test_the_callers_numpy_error_state_holds_in_the_workers(tmp_path, monkeypatch):
    """A float64 column beyond float32 is cast with gb.load's errors ignored in every worker, as in one thread: no
    RuntimeWarning (an error under a strict filter), only the dropped splats' warning."""
    path = raw_ply(tmp_path / "s.ply", 3001, seed=6, dtypes={"x": "f8"})
    v = plyfile.PlyData.read(str(path), mmap=False)
    v["vertex"].data["x"][[5, 2900]] = 1e300
    v.write(str(path))
    monkeypatch.setattr(load_progress, "MIN_BYTES", 1)
    monkeypatch.setattr(os, "cpu_count", lambda: 3)  # workers, whose numpy error state is their own
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("error", RuntimeWarning)
        warnings.simplefilter("always", UserWarning)
        scene = gb.load(path)
    assert scene.num_splats == 2999 and [str(w.message).count("dropped 2 of 3001") for w in caught] == [1]


def test_other_ply_formats_are_not_streamed():
    assert load_streamed_ply(SEEDS / "compressed" / "sh1.ply") is None


@pytest.mark.parametrize("name", ["fruit_drops_minimal.ply", "v3dg-donut.fused.ply"])
def test_shared_inria_scenes_load_as_before(name):
    path = shared_scene(name)
    assert_same(gb.load(path), mapped(path))
    assert_same(gb.load(path), reference(path))


def test_a_few_missing_bytes_are_truncated(tmp_path):
    """Fewer bytes missing than the header check's slack: the streamed read itself says so."""
    path = tmp_path / "t.ply"
    path.write_bytes(ply_header(10, BASE + TAIL) + np.zeros((10, len(BASE + TAIL)), "<f4").tobytes()[:-5])
    with pytest.raises(gb.SceneFormatError, match="truncated"):
        gb.load(path)


def full_checks(path: Path, sh_dtype: str) -> gb.Scene:
    """The loader before the native scatter: plyfile's whole-file decode, the float16 range check of the DC block
    then the rest, activations in numpy, and every check of Scene.from_arrays (no `checked`)."""
    v = plyfile.PlyData.read(str(path), mmap=False)["vertex"].data
    col = lambda *cols: np.stack([np.asarray(v[c], np.float32) for c in cols], axis=1)  # noqa: E731
    rest = sorted((c for c in v.dtype.names if c.startswith("f_rest_")), key=lambda c: int(c[7:]))
    check_sh_range(col("f_dc_0", "f_dc_1", "f_dc_2"), np.dtype(sh_dtype))
    if rest:
        check_sh_range(col(*rest), np.dtype(sh_dtype))
    scene = decode(path)  # from_arrays of the float32 SH: the same splats dropped as of its float16 rounding
    return replace(scene, sh=scene.sh.astype(sh_dtype))


def outcome(fn, path: Path) -> tuple:
    """('ok', scene, warnings) or ('error', message), their words after the file's name."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            scene = fn()
        except gb.GBViewerError as exc:
            return "error", str(exc).removeprefix(f"{path}: ")
    return "ok", scene, sorted(str(w.message).removeprefix(f"{path}: ") for w in caught)


@pytest.mark.parametrize("sh_dtype", ["float32", "float16"])
@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_values_at_the_edges_of_the_checks_load_as_the_full_checks_do(tmp_path, layout, sh_dtype, chunks):
    path = raw_ply(
        tmp_path / "e.ply", 2000, seed=5, extremes=EDGES if sh_dtype == "float32" else HALF_EDGES, **LAYOUTS[layout]
    )
    if LAYOUTS[layout].get("sort_free") is not None:  # the globals row stays valid
        patch_info(path)
    got, want = (
        outcome(lambda: gb.load(path, sh_dtype=sh_dtype), path),
        outcome(lambda: full_checks(path, sh_dtype), path),
    )
    assert got[0] == want[0] == "ok", (got[:2], want[:2])
    assert got[2] == want[2] and any("dropped" in w for w in got[2])  # the same splats dropped, the same words
    assert_same(got[1], want[1])


def patch_info(path: Path) -> None:
    ply = plyfile.PlyData.read(str(path), mmap=False)
    ply["vertex"].data["info"][:2] = (0.05, 8.0)
    ply.write(str(path))


@pytest.mark.parametrize("where", ["f_dc_1", "f_rest_30"])
@pytest.mark.parametrize("big", [65520.0, np.inf, 1e30])
def test_float16_refusals_name_the_same_coefficient(tmp_path, where, big, chunks):
    path = raw_ply(tmp_path / "h.ply", 300, seed=2)
    ply = plyfile.PlyData.read(str(path), mmap=False)
    ply["vertex"].data[where][[7, 250]] = (big / 2, big)
    ply.write(str(path))
    got = outcome(lambda: gb.load(path, sh_dtype="float16"), path)
    want = outcome(lambda: full_checks(path, "float16"), path)
    if chunks:  # a chunk per hundredth: the first chunk with a refused value names its own largest
        assert got[0] == "error" and "beyond float16's range" in got[1]
    else:
        assert got == want and got[0] == "error", (got, want)


def test_quaternion_norms_sum_in_einsums_order():
    """The native scatter and Scene.from_arrays sum |q|^2 as (w^2 + x^2) + (y^2 + z^2): numpy's einsum, which
    normalised the quaternions before them, gives the same bits."""
    from gbviewer.model.scene import _norms

    q = np.concatenate(
        [
            np.random.default_rng(1).normal(0, 1, (200_000, 4)) * np.logspace(-20, 19, 200_000)[:, None],
            QUATS[np.isfinite(QUATS).all(axis=1)],
        ]
    ).astype(np.float32)
    with np.errstate(over="ignore"):
        np.testing.assert_array_equal(_norms(q), np.sqrt(np.einsum("ij,ij->i", q, q)), strict=True)
