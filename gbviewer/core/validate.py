"""Untrusted numbers and documents (command line, file headers, JSON) turned into checked values.

Every option and loader goes through these, so a new one cannot forget a check: finite, in range, integral where
it must be, representable in the type it is cast to (float32 included), declared counts within what the bytes
present can hold, JSON bounded in size and depth. Failures raise `InvalidValue` whose message names `what`.
"""

from __future__ import annotations

import errno
import json
import math
import os
import stat
from pathlib import Path
from typing import Any, BinaryIO, Callable, TypeVar

import numpy as np

from .errors import InvalidValue

T = TypeVar("T")

F32_MAX = float(np.finfo(np.float32).max)
F32_TINY = float(np.finfo(np.float32).tiny)  # the smallest normal float32: a positive value below it underflows
JSON_MAX_BYTES = 64 << 20
JSON_MAX_DEPTH = 32


def _describe(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def real(
    value: object,
    what: str,
    *,
    lo: float | None = None,
    hi: float | None = None,
    lo_open: bool = False,
    f32: bool = False,
) -> float:
    """`value` as a finite float in [lo, hi] ((lo, hi] with lo_open); with f32 it must also fit a float32, and a
    value that must be > 0 must stay so as a normal float32 (a focal length of 1e-45 would become 0 or subnormal)."""
    if isinstance(value, bool):
        raise InvalidValue(f"{what}: expected a number, got {_describe(value)}")
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError, OverflowError):
        raise InvalidValue(f"{what}: expected a number, got {_describe(value)}") from None
    if not math.isfinite(x) or (f32 and abs(x) > F32_MAX):
        kind = "a finite float32 number" if f32 else "a finite number"
        raise InvalidValue(f"{what}: expected {kind}, got {_describe(value)}")
    if lo is not None and (x <= lo if lo_open else x < lo):
        raise InvalidValue(f"{what}: expected {'>' if lo_open else '>='} {lo:g}, got {x:g}")
    if f32 and lo_open and lo == 0 and x < F32_TINY:
        raise InvalidValue(
            f"{what}: expected >= {F32_TINY:.4g} (a positive float32 that does not underflow), got {x:g}"
        )
    if hi is not None and x > hi:
        raise InvalidValue(f"{what}: expected <= {hi:g}, got {x:g}")
    return x


def integer(value: object, what: str, *, lo: int | None = None, hi: int | None = None) -> int:
    """`value` as an int in [lo, hi]; integral floats (2.0) pass, 2.5, NaN, booleans and 5000-digit texts do not."""
    if isinstance(value, bool):
        raise InvalidValue(f"{what}: expected an integer, got {_describe(value)}")
    if isinstance(value, str):
        text = value.strip()
        if len(text) > 40:
            raise InvalidValue(f"{what}: expected an integer, got {_describe(value)}")
        try:
            value = int(text)
        except ValueError:
            try:
                value = float(text)  # "2.0", "1e3"; "nan", "inf" and "1e400" are refused below
            except ValueError:
                raise InvalidValue(f"{what}: expected an integer, got {_describe(value)}") from None
    if isinstance(value, (float, np.floating)):
        x = real(value, what)
        if not x.is_integer():
            raise InvalidValue(f"{what}: expected an integer, got {x:g}")
        value = int(x)
    if not isinstance(value, (int, np.integer)):
        raise InvalidValue(f"{what}: expected an integer, got {_describe(value)}")
    n = int(value)
    if lo is not None and n < lo:
        raise InvalidValue(f"{what}: expected >= {lo}, got {n}")
    if hi is not None and n > hi:
        raise InvalidValue(f"{what}: expected <= {hi}, got {_describe(n)}")
    return n


def distinct_items(text: str, what: str, parse: Callable[[str], T], key: Callable[[T], Any] = lambda v: v) -> list[T]:
    """Comma-separated `text` parsed item by item: at least one, no empty item, no two with the same `key` (the
    same rate twice biases an average, the same mode twice is the same work twice); `InvalidValue` naming `what`."""
    items = text.split(",")
    if any(not item.strip() for item in items):
        raise InvalidValue(f"{what}: empty item in {text!r:.80} (expected comma-separated values, none empty)")
    out: list[T] = []
    seen: dict[Any, str] = {}
    for item in items:
        value = parse(item)
        k = key(value)
        if k in seen:
            raise InvalidValue(f"{what}: {item.strip()!r:.40} repeats {seen[k]!r:.40} in {text!r:.80} (give each once)")
        seen[k] = item.strip()
        out.append(value)
    return out


def array(value: object, what: str, shape: tuple[int, ...], *, f32: bool = False) -> np.ndarray:
    """`value` (nested lists or an array) as a float64 array of exactly `shape` whose entries are finite numbers
    (float32-representable with f32): a pose, a position, a colour."""
    expected = f"a {'x'.join(map(str, shape))} matrix" if len(shape) > 1 else f"{shape[0]} numbers"
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        a = None
    if a is None or a.shape != shape or isinstance(value, (str, bytes)):
        raise InvalidValue(f"{what}: expected {expected}, got {_describe(value)}")
    bad = ~np.isfinite(a) | (np.abs(a) > F32_MAX if f32 else False)
    if bad.any():
        kind = "finite float32 numbers" if f32 else "finite numbers"
        raise InvalidValue(f"{what}: expected {kind}, got {a[bad][0]:g}")
    return a


def declared_count(value: object, what: str, *, item_bytes: int, available: int) -> int:
    """A count a file declares, checked against the bytes actually present before anything is allocated:
    `value` items of at least `item_bytes` each must fit in `available` bytes."""
    n = integer(value, what, lo=0)
    if n * max(item_bytes, 1) > available:
        raise InvalidValue(f"{what}: declares {n} entries of >= {item_bytes} bytes but only {available} bytes follow")
    return n


def _reject_constant(name: str) -> float:
    raise ValueError(f"{name} is not a finite number")


def _one_value_per_key(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in pairs:
        if out.setdefault(key, value) != value:
            raise ValueError(f"key {key!r:.60} given twice with different values")
    return out


def _finite_float(text: str) -> float:
    x = float(text)
    if not math.isfinite(x):
        raise ValueError(f"{text[:20]} is not a finite number")  # 1e400 would parse as inf
    return x


def _depth(doc: Any, limit: int) -> int:
    """Nesting depth of a parsed JSON document (iterative, so it cannot recurse too deep itself)."""
    deepest, stack = 0, [(doc, 1)]
    while stack:
        node, d = stack.pop()
        if isinstance(node, (list, dict)):
            deepest = max(deepest, d)
            if deepest > limit:
                break
            stack.extend((child, d + 1) for child in (node.values() if isinstance(node, dict) else node))
    return deepest


def parse_json(
    text: str | bytes, what: str, *, max_bytes: int = JSON_MAX_BYTES, max_depth: int = JSON_MAX_DEPTH
) -> Any:
    """A JSON document with its size, nesting depth and numbers bounded: `NaN`/`Infinity` and integers too long
    to convert are errors, as are documents over `max_bytes` or nested deeper than `max_depth`, and an object that
    gives one key two different values (JSON readers disagree on which one holds)."""
    if len(text) > max_bytes:
        raise InvalidValue(f"{what}: {len(text)} bytes of JSON, more than the {max_bytes} allowed")
    try:
        doc = json.loads(
            text, parse_constant=_reject_constant, parse_float=_finite_float, object_pairs_hook=_one_value_per_key
        )
    except RecursionError:
        raise InvalidValue(f"{what}: JSON nested deeper than {max_depth} levels") from None
    except (ValueError, UnicodeDecodeError) as exc:
        raise InvalidValue(f"{what}: not valid JSON ({str(exc).splitlines()[0]})") from None
    if _depth(doc, max_depth) > max_depth:
        raise InvalidValue(f"{what}: JSON nested deeper than {max_depth} levels")
    return doc


def finite_json(doc: Any) -> Any:
    """`doc` with every non-finite float (NaN, +-Infinity: a value that over- or underflowed, or is undefined) as
    None, so that it serialises as strict JSON's null; tuples become lists."""
    if isinstance(doc, (float, np.floating)):
        return float(doc) if math.isfinite(doc) else None
    if isinstance(doc, dict):
        return {k: finite_json(v) for k, v in doc.items()}
    if isinstance(doc, (list, tuple)):
        return [finite_json(v) for v in doc]
    return doc


def dumps_json(doc: Any, indent: int | None = None) -> str:
    """Strict JSON of `doc`: only finite numbers, each non-finite one written null (`finite_json`)."""
    return json.dumps(finite_json(doc), indent=indent, allow_nan=False)


def open_regular(path: str | Path) -> BinaryIO:
    """`path` opened to read bytes when it is a regular file (or a link to one), else OSError "not a regular file":
    a FIFO's open waits for a writer and a device may never end, so it is opened without blocking to find out."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a regular file", str(path))
    except BaseException:
        os.close(fd)
        raise
    return open(fd, "rb")


def read_json(path: str | Path, *, max_bytes: int = JSON_MAX_BYTES, max_depth: int = JSON_MAX_DEPTH) -> Any:
    """`parse_json` of a file (a regular one: `open_regular`), reading at most `max_bytes` + 1 bytes of it; errors
    name the file."""
    path = Path(path)
    try:
        with open_regular(path) as fh:
            data = fh.read(max_bytes + 1)
    except OSError as exc:
        raise InvalidValue(f"{path}: cannot read ({exc.strerror or exc})") from None
    return parse_json(data, str(path), max_bytes=max_bytes, max_depth=max_depth)


def field(doc: Any, key: str, what: str) -> Any:
    """`doc[key]` of a JSON object, with a one-line error naming `what` when doc is not an object or lacks key."""
    if not isinstance(doc, dict):
        raise InvalidValue(f"{what}: expected a JSON object, got {type(doc).__name__}")
    if key not in doc:
        raise InvalidValue(f"{what}: missing '{key}'")
    return doc[key]


NPY_HEADER_READERS = {(1, 0): np.lib.format.read_array_header_1_0, (2, 0): np.lib.format.read_array_header_2_0}


def read_npy(fh: BinaryIO, what: str, shapes: list[tuple[int, ...]], dtype: np.dtype) -> np.ndarray:
    """One .npy array from the binary file `fh`, read as the untrusted input it is: its header must say `dtype`,
    one of `shapes` and C order before any data is read (so it allocates no more than expected), its data fill
    that shape exactly; else ValueError naming `what`."""
    version = np.lib.format.read_magic(fh)
    if version not in NPY_HEADER_READERS:
        raise ValueError(f"{what}: .npy format version {version}, expected 1.0 or 2.0")
    got_shape, fortran, got_dtype = NPY_HEADER_READERS[version](fh, max_header_size=1 << 12)
    if got_shape not in shapes or got_dtype != dtype or fortran:
        raise ValueError(
            f"{what} is {got_dtype} {got_shape}{' (Fortran order)' if fortran else ''}, expected "
            f"{dtype} {' or '.join(map(str, shapes))}"
        )
    out = np.empty(got_shape, dtype)
    buf = memoryview(out.reshape(-1).view(np.uint8))
    got = 0
    while got < len(buf):
        n = fh.readinto(buf[got:])
        if not n:
            raise ValueError(f"{what}: data ends after {got} of {len(buf)} bytes")
        got += n
    if fh.read(1):
        raise ValueError(f"{what}: data runs past its {len(buf)} bytes")
    return out
