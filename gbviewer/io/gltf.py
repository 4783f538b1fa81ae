"""glTF 2.0 containers: a `.glb` (12-byte header, JSON chunk, optional BIN chunk) or a `.gltf` JSON document whose
buffers are base64 data URIs or files beside it, and its accessors (strided, normalised integers, sparse) read as
float arrays, every index, offset and count checked against the bytes that hold it before anything is allocated
(Khronos glTF 2.0 specification, "Binary Data Storage" and "Accessors").

Parsed here rather than with pygltflib: the splat reader needs only buffers, bufferViews, accessors and nodes, and
pygltflib checks none of a hostile file's indices, offsets or counts, which would have to be checked here anyway.
"""

from __future__ import annotations

import base64
import binascii
import re
import struct
import urllib.parse
from pathlib import Path, PurePosixPath

import numpy as np

from ..core.errors import InvalidValue, SceneFormatError
from ..core.validate import parse_json
from .progress import LoadProgress

GLB_MAGIC = b"glTF"
GLB_HEADER = struct.Struct("<4sII")
CHUNK_HEADER = struct.Struct("<II")
JSON_CHUNK, BIN_CHUNK = 0x4E4F534A, 0x004E4942
GLTF_JSON_MAX_BYTES = 1 << 31  # a .gltf with embedded buffers is JSON as large as its data; the file bounds it
FLOAT, UBYTE, USHORT, UINT = 5126, 5121, 5123, 5125
COMPONENTS = {5120: "i1", UBYTE: "u1", 5122: "<i2", USHORT: "<u2", UINT: "<u4", FLOAT: "<f4"}
NORMALISERS = {5120: 127.0, UBYTE: 255.0, 5122: 32767.0, USHORT: 65535.0}  # glTF's normalised-integer divisors
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
MAX_STRIDE = 252  # glTF: bufferView.byteStride is at most 252
_DATA_URI = re.compile(r"data:[^;,]*;base64,", re.IGNORECASE)


def is_glb(head: bytes) -> bool:
    return head[:4] == GLB_MAGIC


def looks_like_gltf(path: Path, head: bytes) -> bool:
    """A JSON file that is a glTF document: named .gltf, or with glTF's required `asset` object near its start."""
    return head.lstrip().startswith(b"{") and (path.suffix.lower() == ".gltf" or b'"asset"' in head)


class Gltf:
    """A parsed glTF document and its buffers; `element`, `accessor` and `view_bytes` check what they index."""

    def __init__(self, path: Path, doc: dict, buffers: list[memoryview], glb: bool, size: int) -> None:
        self.path, self.doc, self.buffers, self.glb = path, doc, buffers, glb
        self.size = size + sum(len(b) for b in buffers)  # bytes of the file and its buffers: what bounds counts

    def error(self, message: str, field: str | None = None) -> SceneFormatError:
        return SceneFormatError(self.path, message, field=field)

    def element(self, key: str, index: object, where: str) -> dict:
        """doc[key][index], an object, or a one-line error naming `where` (the field that gave the index)."""
        items = self.doc.get(key, [])
        if not isinstance(items, list) or not _is_index(index) or index >= len(items):
            raise self.error(
                f"index {index!r} is not one of the {len(items) if isinstance(items, list) else 0} {key}", where
            )
        item = items[index]
        if not isinstance(item, dict):
            raise self.error(f"{key}[{index}] is not a JSON object", where)
        return item

    def view_bytes(self, index: object, where: str) -> tuple[memoryview, int]:
        """A bufferView's bytes and its byteStride (0: tightly packed)."""
        view = self.element("bufferViews", index, where)
        buffer = self.buffers[_index_in(self, view, "buffer", len(self.buffers), f"bufferViews[{index}].buffer")]
        offset = _count(self, view, "byteOffset", f"bufferViews[{index}]", 0)
        length = _count(self, view, "byteLength", f"bufferViews[{index}]")
        stride = _count(self, view, "byteStride", f"bufferViews[{index}]", 0)
        if offset + length > len(buffer):
            raise self.error(
                f"bytes {offset}..{offset + length} lie beyond its buffer's {len(buffer)}", f"bufferViews[{index}]"
            )
        if stride and not 4 <= stride <= MAX_STRIDE:
            raise self.error(f"byteStride {stride}; expected 4..{MAX_STRIDE}", f"bufferViews[{index}]")
        return buffer[offset : offset + length], stride

    def accessor(
        self, index: object, where: str, width: int, allowed: dict[int, tuple[bool, ...]], count: int | None = None
    ) -> np.ndarray:
        """Accessor `index` as (count, width) float32 (normalised integers divided as glTF says, the others
        converted as they are), its type and componentType/normalized checked against `allowed`
        ({componentType: allowed normalized flags}) and, given `count`, its count."""
        acc = self.element("accessors", index, where)
        name = f"accessors[{index}] ({where})"
        ctype, norm, kind = acc.get("componentType"), acc.get("normalized", False), acc.get("type")
        if not isinstance(kind, str) or WIDTHS.get(kind) != width:
            raise self.error(f"type {kind!r}; expected {_type_name(width)}", name)
        if not _is_index(ctype) or ctype not in allowed or not isinstance(norm, bool) or norm not in allowed[ctype]:
            raise self.error(
                f"componentType {ctype!r}{' normalized' if norm is True else ''} is not allowed here; "
                f"expected {_allowed_text(allowed)}",
                name,
            )
        n = _count(self, acc, "count", name)
        if count is not None and n != count:
            raise self.error(f"count {n}; expected {count} (the POSITION count)", name)
        dtype = np.dtype(COMPONENTS[ctype])
        if "bufferView" in acc:
            data, stride = self.view_bytes(acc["bufferView"], f"{name}.bufferView")
            raw = _strided(self, data, _count(self, acc, "byteOffset", name, 0), stride, n, width, dtype, name)
        else:  # all zeros, as glTF defines an accessor without a bufferView (sparse values may follow)
            if n > self.size:
                raise self.error(
                    f"count {n} without a bufferView: more elements than the file's {self.size} bytes could describe",
                    name,
                )
            raw = np.zeros((n, width), dtype)
        if "sparse" in acc:
            raw = self._sparse(acc["sparse"], raw, dtype, name)
        out = raw.astype(np.float32)
        if norm:
            out = np.maximum(out / np.float32(NORMALISERS[ctype]), np.float32(-1))
        return out

    def _sparse(self, sparse: object, base: np.ndarray, dtype: np.dtype, name: str) -> np.ndarray:
        """`base` with the rows a sparse substitution names replaced (indices strictly increasing, in range)."""
        where = f"{name}.sparse"
        if (
            not isinstance(sparse, dict)
            or not isinstance(sparse.get("indices"), dict)
            or not isinstance(sparse.get("values"), dict)
        ):
            raise self.error("expected an object with count, indices and values", where)
        k = _count(self, sparse, "count", where)
        if not 1 <= k <= len(base):
            raise self.error(f"count {k}; expected 1..{len(base)} (the accessor's count)", where)
        ind, val = sparse["indices"], sparse["values"]
        itype = ind.get("componentType")
        if itype not in (UBYTE, USHORT, UINT):
            raise self.error(f"componentType {itype!r}; expected 5121, 5123 or 5125", f"{where}.indices")
        idata, _ = self.view_bytes(ind.get("bufferView"), f"{where}.indices.bufferView")
        vdata, _ = self.view_bytes(val.get("bufferView"), f"{where}.values.bufferView")
        rows = _strided(
            self,
            idata,
            _count(self, ind, "byteOffset", where, 0),
            0,
            k,
            1,
            np.dtype(COMPONENTS[itype]),
            f"{where}.indices",
        )[:, 0].astype(np.int64)
        if (np.diff(rows) <= 0).any() or rows[-1] >= len(base):
            raise self.error(f"indices must increase strictly and stay below {len(base)}", f"{where}.indices")
        values = _strided(
            self, vdata, _count(self, val, "byteOffset", where, 0), 0, k, base.shape[1], dtype, f"{where}.values"
        )
        out = np.array(base)
        out[rows] = values
        return out


def read_gltf(path: Path, progress: LoadProgress) -> Gltf:
    """Read a `.glb` or `.gltf` and the buffers it names (reported as bytes of the file itself)."""
    data = memoryview(progress.read_file(path))
    binary = None
    if is_glb(data[:4]):
        json_bytes, binary = _glb_chunks(path, data)
        limit = len(json_bytes)
    else:
        json_bytes, limit = data, GLTF_JSON_MAX_BYTES
    try:
        doc = parse_json(bytes(json_bytes), "glTF JSON", max_bytes=max(limit, 1))
    except InvalidValue as exc:
        raise SceneFormatError(path, str(exc)) from None
    if not isinstance(doc, dict):
        raise SceneFormatError(path, "the glTF JSON is not an object")
    version = doc.get("asset", {}).get("version") if isinstance(doc.get("asset"), dict) else None
    if not isinstance(version, str) or not version.startswith("2."):
        raise SceneFormatError(path, f"glTF asset.version {version!r}; expected 2.x", field="asset")
    buffers = doc.get("buffers", [])
    if not isinstance(buffers, list):
        raise SceneFormatError(path, "expected a list", field="buffers")
    return Gltf(path, doc, [_buffer(path, b, i, binary) for i, b in enumerate(buffers)], is_glb(data[:4]), len(data))


def _glb_chunks(path: Path, data: memoryview) -> tuple[memoryview, memoryview | None]:
    if len(data) < GLB_HEADER.size + CHUNK_HEADER.size:
        raise SceneFormatError(path, f"{len(data)} bytes; a .glb needs at least 20", field="header")
    _, version, length = GLB_HEADER.unpack_from(data)
    if version != 2:
        raise SceneFormatError(path, f"GLB version {version}; expected 2", field="header")
    if length > len(data):
        raise SceneFormatError(
            path, f"header says {length} bytes, the file has {len(data)} (truncated?)", field="header"
        )
    chunks: list[tuple[int, memoryview]] = []
    pos = GLB_HEADER.size
    while pos + CHUNK_HEADER.size <= length:
        size, kind = CHUNK_HEADER.unpack_from(data, pos)
        pos += CHUNK_HEADER.size
        if pos + size > length:
            raise SceneFormatError(
                path, f"chunk at {pos - 8} of {size} bytes overruns the file's {length}", field="chunks"
            )
        chunks.append((kind, data[pos : pos + size]))
        pos += size
    if not chunks or chunks[0][0] != JSON_CHUNK:
        raise SceneFormatError(path, "the first chunk must be the JSON chunk", field="chunks")
    binary = chunks[1][1] if len(chunks) > 1 and chunks[1][0] == BIN_CHUNK else None
    return chunks[0][1], binary


def _buffer(path: Path, buf: object, i: int, binary: memoryview | None) -> memoryview:
    where = f"buffers[{i}]"
    if not isinstance(buf, dict):
        raise SceneFormatError(path, "expected an object", field=where)
    length = buf.get("byteLength")
    if not _is_index(length):
        raise SceneFormatError(path, f"byteLength {length!r}; expected an integer >= 0", field=where)
    uri = buf.get("uri")
    if uri is None:
        if i != 0 or binary is None:
            raise SceneFormatError(
                path, "no uri, and it is not the first buffer of a .glb with a BIN chunk", field=where
            )
        data = binary
    elif not isinstance(uri, str):
        raise SceneFormatError(path, f"uri {uri!r}; expected a string", field=where)
    elif (m := _DATA_URI.match(uri)) is not None:
        if (len(uri) - m.end()) * 3 // 4 < length:
            raise SceneFormatError(path, f"the data URI holds fewer than its byteLength {length} bytes", field=where)
        try:
            data = memoryview(base64.b64decode(uri[m.end() :], validate=True))
        except (binascii.Error, ValueError) as exc:
            raise SceneFormatError(path, f"bad base64 in the data URI: {exc}", field=where) from None
    else:
        data = _external(path, urllib.parse.unquote(uri), length, where)
    if len(data) < length:
        raise SceneFormatError(path, f"holds {len(data)} bytes; byteLength says {length}", field=where)
    return data[:length]


def _external(path: Path, uri: str, length: int, where: str) -> memoryview:
    """A buffer file beside the .gltf: a relative path that stays inside its folder, at least `length` bytes."""
    rel = PurePosixPath(uri)
    if rel.is_absolute() or ".." in rel.parts or ":" in uri.split("/")[0] or not uri:
        raise SceneFormatError(path, f"uri {uri[:80]!r} must be a relative path inside the .gltf's folder", field=where)
    target = path.parent / rel
    try:
        with open(target, "rb") as fh:
            data = fh.read(length)
    except OSError as exc:
        raise SceneFormatError(path, f"cannot read {target} ({exc.strerror or exc})", field=where) from None
    return memoryview(data)


def _strided(
    gl: Gltf, data: memoryview, offset: int, stride: int, n: int, width: int, dtype: np.dtype, where: str
) -> np.ndarray:
    """(n, width) elements of `dtype` starting `offset` bytes into `data`, `stride` bytes apart (0: packed),
    checked to lie inside `data` before the view is made."""
    elem = width * dtype.itemsize
    step = stride or elem
    if stride and stride < elem:
        raise gl.error(f"byteStride {stride} is shorter than the {elem}-byte element", where)
    end = offset + (n - 1) * step + elem if n else offset
    if end > len(data):
        raise gl.error(
            f"{n} elements of {elem} bytes every {step} from byte {offset} need {end} bytes; the "
            f"bufferView has {len(data)}",
            where,
        )
    if n == 0:
        return np.zeros((0, width), dtype)
    return np.ndarray((n, width), dtype, buffer=data, offset=offset, strides=(step, dtype.itemsize))


def _is_index(v: object) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _count(gl: Gltf, obj: dict, key: str, where: str, default: int | None = None) -> int:
    v = obj.get(key, default)
    if not _is_index(v):
        raise gl.error(f"{key} {v!r}; expected an integer >= 0", where)
    return v


def _index_in(gl: Gltf, obj: dict, key: str, size: int, where: str) -> int:
    v = obj.get(key)
    if not _is_index(v) or v >= size:
        raise gl.error(f"{v!r} is not an index below {size}", where)
    return v


def _type_name(width: int) -> str:
    return next(k for k, v in WIDTHS.items() if v == width)


def _allowed_text(allowed: dict[int, tuple[bool, ...]]) -> str:
    names = {
        5120: "byte",
        UBYTE: "unsigned byte",
        5122: "short",
        USHORT: "unsigned short",
        UINT: "unsigned int",
        FLOAT: "float",
    }
    return ", ".join(f"{names[c]}{' normalized' if n else ''}" for c, flags in allowed.items() for n in flags)
