"""A level-of-detail cache entry is untrusted input: every hostile or damaged entry (a repeated leaf index, values
out of range, wrong dtypes, shapes or members, a lying header) is rebuilt with one warning naming the file, and the
native cut and upload cannot be driven out of bounds by a tree that skipped the Python checks."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import random_scene

import gbviewer as gb
from gbviewer import lod
from gbviewer.io.write import write_inria_ply
from gbviewer.lod.cache import cached_build
from gbviewer.lod.entry import read_entry


def entry_of(tmp_path: Path, n: int = 600, filter3d: bool = False) -> tuple[gb.Scene, lod.Hierarchy, Path]:
    scene = random_scene(n, seed=5, sh_degree=1)
    if filter3d:
        scene = gb.Scene.from_arrays(
            scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, np.full(n, 0.01)
        )
    scene = gb.load(write_inria_ply(scene, tmp_path / "s.ply"))
    cache = tmp_path / "cache"
    tree = cached_build(scene, "depth", cache)
    (entry,) = cache.glob("*.npz")
    return scene, tree, entry


def npz(arrays: dict[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def set_(name, index, value):
    def edit(a):
        a[name] = a[name].copy()
        a[name][index] = value

    return edit


def repeat_leaf(a):
    a["order"] = a["order"].copy()
    a["order"][1] = a["order"][0]


HOSTILE = {
    "repeated leaf": repeat_leaf,
    "leaf out of range": set_("order", 3, 10**6),
    "negative leaf": set_("order", 0, -1),
    "NaN mean": set_("means", (2, 1), np.nan),
    "inf radius": set_("radius", 0, np.inf),
    "negative size": set_("size", 1, -0.5),
    "negative scale": set_("scales", (0, 0), -1.0),
    "opacity 1e30": set_("opacities", 0, 1e30),
    "negative opacity": set_("opacities", 0, -0.1),
    "quat not unit": set_("quats", 0, [2.0, 0, 0, 0]),
    "sh beyond limits": set_("sh", (0, 0, 0), 3e38),
    "levels off": set_("levels", -1, 10**9),
    "float64 means": lambda a: a.update(means=a["means"].astype(np.float64)),
    "int64 order": lambda a: a.update(order=a["order"].astype(np.int64)),
    "short sh": lambda a: a.update(sh=a["sh"][:-1]),
    "fortran scales": lambda a: a.update(scales=np.asfortranarray(a["scales"])),
    "missing size": lambda a: a.pop("size"),
    "extra member": lambda a: a.update(extra=np.zeros(3)),
    "filter_3d for a scene without one": lambda a: a.update(filter_3d=np.zeros(len(a["size"]), np.float32)),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_a_hostile_entry_is_rebuilt_with_one_warning_naming_it(tmp_path, case):
    scene, tree, entry = entry_of(tmp_path)
    arrays = dict(tree.arrays())
    HOSTILE[case](arrays)
    entry.write_bytes(npz(arrays))
    with pytest.warns(UserWarning, match="damaged level-of-detail cache entry") as caught:
        rebuilt = cached_build(scene, "depth", entry.parent)
    assert len(caught) == 1 and str(entry) in str(caught[0].message)
    assert all(np.array_equal(a, b) for a, b in zip(tree.arrays().values(), rebuilt.arrays().values()))
    assert entry.read_bytes() == npz(tree.arrays())  # rewritten whole: read back without a warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        cached_build(scene, "depth", entry.parent)


def member(name: str, header: bytes, data: bytes) -> tuple[str, bytes]:
    return f"{name}.npy", b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + data


@pytest.mark.parametrize("case", ["lying shape", "trailing data", "pickled object array", "deflated bomb"])
def test_an_entry_is_refused_from_its_headers_before_its_data(tmp_path, case):
    """A member whose header claims more than the scene's tree (or data beyond it) is refused without reading
    it all: a 1 GB deflated member of zeros costs a few kilobytes of its stream."""
    scene, tree, entry = entry_of(tmp_path)
    arrays = dict(tree.arrays())
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, a in arrays.items():
            if name == "radius":
                if case == "lying shape":
                    z.writestr(
                        *member(name, b"{'descr': '<f4', 'fortran_order': False, 'shape': (10000000,), }", a.tobytes())
                    )
                elif case == "trailing data":
                    z.writestr(
                        *member(
                            name,
                            f"{{'descr': '<f4', 'fortran_order': False, 'shape': ({len(a)},), }}".encode(),
                            a.tobytes() + b"\0" * 4,
                        )
                    )
                elif case == "pickled object array":
                    z.writestr(*member(name, b"{'descr': '|O', 'fortran_order': False, 'shape': (3,), }", b"\x80"))
                else:
                    with z.open(f"{name}.npy", "w", force_zip64=True) as fh:
                        fh.write(
                            b"\x93NUMPY\x01\x00"
                            + (74).to_bytes(2, "little")
                            + b"{'descr': '<f4', 'fortran_order': False, 'shape': (250000000,), }".ljust(73)
                            + b"\n"
                        )
                        for _ in range(1000):
                            fh.write(bytes(1 << 20))
                continue
            z.writestr(f"{name}.npy", npz_member(a))
    entry.write_bytes(buf.getvalue())
    with pytest.raises(ValueError, match="radius"):
        read_entry(entry, scene, "depth")


def npz_member(a: np.ndarray) -> bytes:
    out = io.BytesIO()
    np.lib.format.write_array(out, a)
    return out.getvalue()


def test_a_valid_entry_reads_back_bit_identical_with_a_3d_filter(tmp_path):
    scene, tree, entry = entry_of(tmp_path, filter3d=True)
    back = read_entry(entry, scene, "depth")
    assert all(
        np.array_equal(a, b) and a.dtype == b.dtype for a, b in zip(tree.arrays().values(), back.arrays().values())
    )


def test_flicker_over_a_repeated_leaf_entry_rebuilds_it(tmp_path):
    """The reported crash: a well-formed entry whose leaf order repeats an index killed `gbviewer flicker ...
    --modes scalar+lod:2,scalar+lod:4` with SIGSEGV (the cut's scatter by splat left weights unwritten)."""
    scene, tree, entry = entry_of(tmp_path, n=3000)
    arrays = dict(tree.arrays())
    repeat_leaf(arrays)
    entry.write_bytes(npz(arrays))
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "xdg")}
    folder = tmp_path / "xdg" / "gbviewer" / "lod"
    folder.mkdir(parents=True)
    os.replace(entry, folder / entry.name)
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "gbviewer",
            "flicker",
            str(tmp_path / "s.ply"),
            "--modes",
            "scalar+lod:2,scalar+lod:4",
            "--pairs",
            "2",
            "--frames",
            "8",
            "--width",
            "64",
            "--height",
            "48",
            "--backend",
            "cpu",
            "--out",
            str(tmp_path / "out"),
        ],
        capture_output=True,
        cwd=tmp_path,
        text=True,
        env=env,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stderr.count("damaged level-of-detail cache entry") == 1
    assert "not a permutation" in out.stderr and str(folder / entry.name) in out.stderr


def test_the_native_cut_stays_in_bounds_whatever_order_it_is_given(tmp_path):
    """Python's checks bypassed: the cut's scatters skip splat indices outside the scene, its levels are checked."""
    from gbviewer._native import lod as native

    scene = random_scene(5000, seed=3)
    tree = lod.build(scene)
    order = tree.order.copy()
    order[::7] = 2**31 - 1
    order[1::7] = -(2**31)
    eye = np.array([0, 0, -50], np.float32)
    code = (
        "import numpy as np, sys; from gbviewer._native import lod as n; d = np.load(sys.argv[1]); "
        "out = n.cut(d['means'], d['radius'], d['size'], d['levels'], d['order'], d['eye'], 500.0, False, 0.5, "
        "1.0, 0, None); assert out is not None; print('ok')"
    )
    np.savez(
        tmp_path / "t.npz",
        means=tree.means,
        radius=tree.radius,
        size=tree.size,
        levels=tree.levels,
        order=order,
        eye=eye,
    )
    done = subprocess.run(
        [sys.executable, "-c", code, str(tmp_path / "t.npz")], capture_output=True, cwd=tmp_path, text=True, timeout=120
    )
    assert done.returncode == 0 and done.stdout.strip() == "ok", done.stderr[-2000:]
    levels = tree.levels.copy()
    levels[2] += 1000  # interior arrays no longer match; the walk would index past them
    with pytest.raises(ValueError, match="lod cut: levels"):
        native.cut(tree.means, tree.radius, tree.size, levels, tree.order, eye, 500.0, False, 0.5, 1.0, 0, None)


@pytest.mark.parametrize("case", ["repeated leaf", "NaN radius", "infinite node opacity"])
def test_upload_lod_refuses_a_tree_the_stage_cannot_draw(case):
    from gbviewer._native import Renderer

    scene = random_scene(500, seed=4)
    tree = lod.build(scene)
    order, radius, opacities = tree.order.copy(), tree.radius.copy(), tree.opacities.copy()
    if case == "repeated leaf":
        order[1] = order[0]
    elif case == "NaN radius":
        radius[0] = np.nan
    else:
        opacities[3] = np.inf
    r = Renderer()
    r.upload(scene.means, scene.scales, scene.quats, scene.opacities, scene.sh, None)
    with pytest.raises(ValueError, match="permutation" if case == "repeated leaf" else "not finite"):
        r.upload_lod(
            tree.means, tree.scales, tree.quats, opacities, tree.sh, None, radius, tree.size, tree.levels, order
        )


def test_a_cache_write_that_raises_leaves_no_tree_behind(tmp_path, monkeypatch):
    """A write failing other than as a read-only cache (here a ValueError from the archive) fails the call and is
    not remembered: the next call builds and writes again, instead of serving the memo of a call that raised."""
    scene = gb.load(write_inria_ply(random_scene(300, seed=7), tmp_path / "m.ply"))
    monkeypatch.setattr(lod.cache, "default_folder", lambda: tmp_path / "cache")
    savez = np.savez

    def broken(*args, **kwargs):
        raise ValueError("archive failed")

    monkeypatch.setattr(np, "savez", broken)
    with pytest.raises(ValueError, match="archive failed"):
        lod.hierarchy_for(scene)
    assert "depth" not in lod.cache._memo.get(scene, {})
    monkeypatch.setattr(np, "savez", savez)
    tree = lod.hierarchy_for(scene)
    assert len(list((tmp_path / "cache").glob("*.npz"))) == 1 and lod.hierarchy_for(scene) is tree


@pytest.mark.parametrize("kind", ["fifo", "link to /dev/zero"])
def test_an_entry_that_is_not_a_regular_file_is_rebuilt_without_blocking(tmp_path, kind):
    """A FIFO (whose open waits for a writer) or a link to an endless device in an entry's place hung the lookup:
    it is refused as any damaged entry, with one warning, and the tree is built and written in its place."""
    scene, tree, entry = entry_of(tmp_path)
    entry.unlink()
    if kind == "fifo":
        os.mkfifo(entry)
    else:
        os.symlink("/dev/zero", entry)
    out = subprocess.run(
        [
            sys.executable,
            "-c",
            (
                "import sys, warnings; from pathlib import Path; import gbviewer as gb; "
                "from gbviewer.lod.cache import cached_build; scene = gb.load(sys.argv[1]); "
                "warnings.simplefilter('always'); cached_build(scene, 'depth', Path(sys.argv[2]))"
            ),
            str(tmp_path / "s.ply"),
            str(entry.parent),
        ],
        capture_output=True,
        cwd=tmp_path,
        text=True,
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert out.stderr.count("damaged level-of-detail cache entry") == 1 and "not a regular file" in out.stderr
    assert not entry.is_symlink() and entry.is_file()
    assert all(
        np.array_equal(a, b)
        for a, b in zip(tree.arrays().values(), read_entry(entry, scene, "depth").arrays().values())
    )


def test_the_shared_tree_is_read_only():
    """hierarchy_for hands every caller the scene's one tree: an edit of its arrays (tree.opacities[:] = 0) changed
    what later cuts gathered (the GLSL and CUDA frames, a re-upload) while the uploaded copy stayed as it was."""
    scene = random_scene(300, seed=9)
    tree = lod.hierarchy_for(scene)
    for _name, a in tree.arrays().items():
        with pytest.raises(ValueError, match="read-only"):
            a[0] = 0
    assert lod.hierarchy_for(scene) is tree
