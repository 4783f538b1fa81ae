"""Scene loading: `load(path)` detects the format by content and returns a validated `Scene`; `progress` reports the
bytes read and the splats decoded, `cancel` stops it (see `progress`)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..core.cancel import Cancellable
from ..core.errors import CallbackError, GBViewerError, LoadCancelled, SceneFormatError
from ..core.files import file_stat
from ..model.camera import load_cameras_json
from ..model.scene import Scene, loaded_from
from .compressed_ply import is_compressed_ply, load_compressed_ply
from .duplex import is_duplex_ply, load_duplex
from .gltf import is_glb, looks_like_gltf
from .gltf_splats import load_gltf
from .ply import check_sh_range, load_inria_ply
from .ply_read import read_ply
from .ply_stream import load_streamed_ply
from .progress import LoadProgress, Progress
from .save import WRITE_FORMATS, dropped, format_for, save
from .sog import ZIP_MAGIC, load_sog
from .splat import load_splat, looks_like_splat
from .spz import GZIP_MAGIC, read_spz
from .spz import MAGIC as SPZ_MAGIC
from .trained_as import ply_comments, resolve, signals_of
from .write import write_inria_ply

__all__ = ["WRITE_FORMATS", "dropped", "format_for", "load", "load_cameras_json", "save", "write_inria_ply"]

SH_DTYPES = ("float32", "float16")
FORMATS = (
    "INRIA (incl. sort-free GS), Duplex-GS or compressed .ply, .spz, .sog (zip, folder or meta.json), .splat or "
    "glTF (.glb/.gltf with KHR_gaussian_splatting)"
)


def load(
    path: str | Path,
    progress: Progress | None = None,
    cancel: Cancellable | None = None,
    sh_dtype: str = "float32",
    primitive: int | None = None,
) -> Scene:
    """Load a splat scene file or SOG folder; the format comes from the content, not the extension.

    `progress`: called as fn(done, total, unit) with unit "bytes" (read from the file), then "splats" (decoded),
    at most about a hundred times per unit, done rising to total; an exception it raises ends the load with a
    CallbackError chained to it. `cancel`: a gbviewer.CancelToken (or threading.Event); once it is set the load
    raises LoadCancelled within one chunk (at most a hundredth of the file or 65536 splats). `sh_dtype`:
    "float16" stores the SH coefficients as float16 (half their memory, rounded to nearest; an error where one is
    beyond float16's range); the renderers convert them to float32 at upload. `scene.meta["trained_as"]` and its
    source: the mode the file says it was trained with (gbviewer.io.trained_as). `scene.content`: the digest of
    the bytes read (every file of a multi-file format), hashed as they are read (what the hierarchy cache keys on);
    None when the file changed during the load. The scene's arrays are read-only. `primitive`: for a glTF file,
    load only its N-th splat primitive (all of them, as one scene, by default)."""
    path = Path(path)
    if sh_dtype not in SH_DTYPES:
        raise GBViewerError(f"sh_dtype {sh_dtype!r}; expected one of {', '.join(SH_DTYPES)}")
    reporter = LoadProgress(progress, cancel)
    try:
        reporter.check()
        before = file_stat(path)
        with np.errstate(all="ignore"):  # overflow in decoding is data: Scene drops non-finite splats with a warning
            scene = _load(path, reporter, sh_dtype, primitive)
            scene.meta.update(resolve(signals_of(scene.meta, ply_comments(path) if path.is_file() else [])))
            if scene.sh.dtype != sh_dtype:  # formats decoded in float32: converted once whole
                scene = replace(scene, sh=check_sh_range(scene.sh, np.dtype(sh_dtype)).astype(sh_dtype))
            unchanged = path.is_dir() or (before is not None and file_stat(path) == before)  # (mapped reads)
            plain = scene.oit is None or scene.oit.neural is None  # a trained model's other files are not hashed
            return loaded_from(scene, reporter.digest.hexdigest() if unchanged and plain else None)
    except (SceneFormatError, LoadCancelled, CallbackError):
        raise
    except GBViewerError as exc:  # Scene validation of decoded data, e.g. every splat non-finite
        raise SceneFormatError(path, str(exc).removeprefix(f"{path}: ")) from None


def _load(path: Path, progress: LoadProgress, sh_dtype: str, primitive: int | None) -> Scene:
    if primitive is not None:
        head = b""
        if path.is_file():
            with open(path, "rb") as fh:
                head = fh.read(1 << 16)
        if not (is_glb(head) or looks_like_gltf(path, head)):
            raise SceneFormatError(path, f"--primitive {primitive}: not a glTF file (only glTF has primitives)")
        return load_gltf(path, progress, primitive)
    if path.is_dir():
        return load_sog(path, progress)
    if not path.is_file():
        raise SceneFormatError(path, "no such file" if not path.exists() else "not a regular file")
    with open(path, "rb") as fh:
        head = fh.read(16)
    if head.startswith(b"ply"):
        streamed = load_streamed_ply(path, progress, sh_dtype)
        if streamed is not None:
            return streamed
        ply = read_ply(path, progress)
        if is_compressed_ply(ply):
            return load_compressed_ply(path, ply, progress)
        return load_duplex(path, ply) if is_duplex_ply(ply) else load_inria_ply(path, ply, progress)
    if is_glb(head):
        return load_gltf(path, progress)
    if head.lstrip().startswith(b"{"):
        with open(path, "rb") as fh:
            json_head = fh.read(1 << 16)
        return load_gltf(path, progress) if looks_like_gltf(path, json_head) else load_sog(path, progress)
    if head.startswith(ZIP_MAGIC):
        return load_sog(path, progress)
    if head.startswith(SPZ_MAGIC) or head.startswith(GZIP_MAGIC):
        return read_spz(path, progress)
    data = progress.read_file(path)
    if looks_like_splat(data):
        return load_splat(path, data, progress)
    raise SceneFormatError(path, f"unrecognised scene format; expected {FORMATS}")
