"""The `Scene` type: activated Gaussian splat parameters as a structure of float32 arrays."""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from ..core.errors import GBViewerError
from .cells import Cells

if TYPE_CHECKING:
    from .camera import Camera

SH_COEFFS = {0: 1, 1: 4, 2: 9, 3: 16}
SH_C0 = 0.28209479177387814  # degree-0 SH basis: colour = 0.5 + SH_C0 * dc
# Splats beyond these are dropped like non-finite ones: the renderers' float32 arithmetic overflows on them.
MAX_SCALE = 1e18  # activated scale: the covariance sums scale^2
MAX_SH = 1e30  # SH coefficient: a colour sums 16 of them times basis values up to ~3, then blends
LIMITS = {"scales": MAX_SCALE, "sh": MAX_SH, "view_weight_sh": MAX_SH}
ARRAYS = ("means", "scales", "quats", "opacities", "sh", "filter_3d")  # a Scene's splat arrays


def sh_degree_for(num_coeffs: int) -> int:
    """SH degree for K = (deg+1)^2 coefficients per channel."""
    for deg, k in SH_COEFFS.items():
        if k == num_coeffs:
            return deg
    raise GBViewerError(f"sh has {num_coeffs} coefficients per channel; expected one of 1, 4, 9, 16")


READ_ONLY = (
    "a Scene's arrays are read-only (a renderer reuses what it derived from them for as long as the Scene "
    "lives); edit a copy: arrays = scene.editable(), then dataclasses.replace(scene, **arrays)"
)


class SceneArray(np.ndarray):
    """A Scene's read-only view of one of its arrays, whose writes (item assignment, in-place operators, a ufunc's
    `out`) fail with READ_ONLY: what to do instead. Computations on it give plain arrays."""

    def __setitem__(self, key, value) -> None:
        if not self.flags.writeable:
            raise ValueError(READ_ONLY)
        super().__setitem__(key, value)

    def __getitem__(self, key):
        out = super().__getitem__(key)
        # a view keeps the type (its writes fail alike); a copy (fancy indexing) is the caller's, plain
        return out.view(np.ndarray) if isinstance(out, np.ndarray) and out.flags.writeable else out

    def __array_ufunc__(self, ufunc, method, *inputs, out=None, **kwargs):
        if out is not None and any(isinstance(o, SceneArray) and not o.flags.writeable for o in out):
            raise ValueError(READ_ONLY)
        if method == "at" and isinstance(inputs[0], SceneArray) and not inputs[0].flags.writeable:
            raise ValueError(READ_ONLY)  # ufunc.at writes in place whatever the flag says (numpy 2.4)
        inputs = tuple(a.view(np.ndarray) if isinstance(a, SceneArray) else a for a in inputs)
        if out is not None:
            kwargs["out"] = tuple(o.view(np.ndarray) if isinstance(o, SceneArray) else o for o in out)
        return getattr(ufunc, method)(*inputs, **kwargs)


def read_only(a: np.ndarray | None, half: bool = False) -> np.ndarray | None:
    """`a` as a Scene holds it: C-contiguous float32 (float16 kept where `half`), a copy where it was not or where
    its memory is not an array's (a bytearray, a mapping: written past numpy's flags); a read-only SceneArray view,
    the array it was given as and every array that one views made read-only too (not edited through those either:
    `sealed` tells whether one was made writable again)."""
    if a is None or isinstance(a, SceneArray) and sealed(a):
        return a
    a = np.asarray(a)
    if not (a.flags.c_contiguous and (a.dtype == np.float32 or half and a.dtype == np.float16)) or not _array_memory(a):
        a = np.array(a, np.float16 if half and a.dtype == np.float16 else np.float32, order="C")
    chain = a
    while isinstance(chain, np.ndarray):
        chain.flags.writeable = False
        chain = chain.base
    return a.view(SceneArray)


def _array_memory(a: np.ndarray) -> bool:
    """Whether `a`'s memory belongs to an array (it, or the array it views), or to a read-only buffer (bytes)."""
    while isinstance(a.base, np.ndarray):
        a = a.base
    if a.base is None:
        return True
    try:
        return memoryview(a.base).readonly
    except TypeError:
        return False


def sealed(a: np.ndarray | None) -> bool:
    """Whether `a` (a Scene's array) and every array it views are still read-only: one made writable again
    (`a.base.flags.writeable = True`, or the array handed to the Scene) may have been edited since."""
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return True


class ViewDecoder(Protocol):
    """A trained model whose splats depend on the view (Duplex-GS: `gbviewer.io.duplex_model.DuplexModel`)."""

    def decode(self, camera: Camera) -> Scene:
        """The splats (and their cells) to render for this camera."""
        ...


@dataclass(frozen=True, eq=False)
class OitData:
    """A scene's data for the order-independent modes (wsr, duplex; docs/modes.md#wsr); every field is optional.

    view_weight_sh (N,K): the sort-free view weight v_i as a raw 1-channel SH (f_do_0, f_ro_*; wsr and duplex
    multiply the opacity by it); sigma (LC-WSR's depth-correction scale) and weight_background: the trained globals
    (ply `info` rows); et_grade: a trained Duplex-GS E; cells: the scene's own Duplex-GS cells; neural: a trained
    Duplex-GS model whose splats are decoded per view (the scene's splat arrays then only hold the view-independent
    centres, for bounds and framing).
    """

    view_weight_sh: np.ndarray | None = None
    sigma: float | None = None
    weight_background: float | None = None
    et_grade: float | None = None
    cells: Cells | None = None
    neural: ViewDecoder | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "view_weight_sh", read_only(self.view_weight_sh))

    def __setstate__(self, state: dict) -> None:
        """Unpickled or deep-copied: read-only again (numpy's pickles restore arrays writable)."""
        self.__dict__.update(state)
        self.__post_init__()


@dataclass(frozen=True, eq=False)
class Checked:
    """A loader's word that it has done `Scene.from_arrays`'s per-value work on its arrays in its own pass over
    them (gbviewer.io's INRIA loader, natively, as it reads them): `keep` (N,) bool marks the splats whose values are
    all finite and within LIMITS; the quaternions are normalised as `unit_quats` does, opacities are in [0, 1],
    filter_3d and scales >= 0 (or NaN, in a splat keep drops). from_arrays then only drops the splats keep
    excludes."""

    keep: np.ndarray


@dataclass(frozen=True, eq=False)
class Scene:
    """Splats with activated parameters, field by field (N splats; float32 unless said):

    means (N,3): centres in world space.
    scales (N,3): standard deviations along the splat's axes (after exp).
    quats (N,4): unit rotation quaternions (w, x, y, z).
    opacities (N,): in [0, 1] (after the sigmoid).
    sh (N,K,3): spherical-harmonics coefficients, K = (degree + 1)^2, DC first (float16 when loaded with
        `gb.load(path, sh_dtype="float16")`; the renderers convert it at upload).
    filter_3d (N,) or None: Mip-Splatting's 3D filter, applied in every mode (docs/modes.md#3d-filter).
    source: the file it was loaded from ("<arrays>" otherwise).
    meta: loader facts (format, version, property names, training mode) for `gbviewer info`.
    oit: the data of the order-independent modes (`OitData`), None for ordinary scenes.
    content: the SHA-256 digest of the bytes a scene was loaded from (`gbviewer.load`), what caches of data derived
        from its splats key on; None for any other scene, one made by `dataclasses.replace` included.

    The arrays are read-only once a Scene holds them (renderers reuse what they derive from them per camera): those
    handed in are made read-only too; `editable()` gives writable copies to make an edited Scene of.
    """

    means: np.ndarray
    scales: np.ndarray
    quats: np.ndarray
    opacities: np.ndarray
    sh: np.ndarray
    filter_3d: np.ndarray | None = None
    source: str = "<arrays>"
    meta: dict[str, Any] = field(default_factory=dict)
    oit: OitData | None = None
    content: str | None = field(default=None, init=False, compare=False, repr=False)

    def __post_init__(self) -> None:
        for name in ARRAYS:
            object.__setattr__(self, name, read_only(getattr(self, name), half=name == "sh"))
        check_shapes(self.arrays, self.source)  # the native renderers index every array by the splat

    def __getstate__(self) -> dict:
        state = dict(self.__dict__)
        if not self.intact:  # maybe edited since it was loaded: no longer its file's content
            state["content"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        """Unpickled or deep-copied: read-only again, as every Scene (numpy's pickles restore arrays writable)."""
        self.__dict__.update(state)
        self.__post_init__()

    def editable(self) -> dict[str, np.ndarray]:
        """Writable copies of the splat arrays by name (filter_3d only when present): edit them, then make the
        edited scene with dataclasses.replace(scene, **arrays) (or Scene.from_arrays, which checks them)."""
        return {name: np.array(a) for name, a in self.arrays.items()}

    @property
    def arrays(self) -> dict[str, np.ndarray]:
        """The splat arrays by name (filter_3d only when present)."""
        return {name: getattr(self, name) for name in ARRAYS if getattr(self, name) is not None}

    @property
    def intact(self) -> bool:
        """Whether no array of the scene can have been written since it was made (each still `sealed`): what the
        renderers and caches derived from it holds. False once an array it was made of was made writable again;
        they then derive it anew each time."""
        extra = [self.oit.view_weight_sh] if self.oit is not None else []
        return all(sealed(a) for a in [*self.arrays.values(), *extra])

    @property
    def num_splats(self) -> int:
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        return sh_degree_for(self.sh.shape[1])

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned bounding box of all splat centres."""
        return self.means.min(axis=0), self.means.max(axis=0)

    def robust_bounds(self, percentile: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of the central splats (per-axis percentiles), ignoring stray far splats. Interpolated in float64:
        float32 differences of coordinates near 1e38 overflow. Column by column: the same values as over axis 0 of
        the (N, 3) array, whose strided partition took most of a second at 6 M splats (framing a scene just opened
        waits for it)."""
        q = [percentile, 100.0 - percentile]
        lo, hi = np.stack([np.percentile(self.means[:, j].astype(np.float64), q) for j in range(3)], axis=1)
        return lo.astype(np.float32), hi.astype(np.float32)

    @classmethod
    def from_arrays(
        cls,
        means: np.ndarray,
        scales: np.ndarray,
        quats: np.ndarray,
        opacities: np.ndarray,
        sh: np.ndarray,
        filter_3d: np.ndarray | None = None,
        source: str = "<arrays>",
        meta: dict[str, Any] | None = None,
        view_weight_sh: np.ndarray | None = None,
        wsr_sigma: float | None = None,
        weight_background: float | None = None,
        et_grade: float | None = None,
        cells: Cells | None = None,
        neural: ViewDecoder | None = None,
        checked: Checked | None = None,
    ) -> "Scene":
        """Validate activated arrays, drop non-finite splats and those beyond LIMITS (warning once), normalise
        quaternions. The keywords from view_weight_sh on make `Scene.oit` (wsr_sigma is `OitData.sigma`).
        `checked`: the loader has done the per-value checks already (`Checked`); only the shapes are checked here."""
        arrays = {
            "means": np.asarray(means, dtype=np.float32),
            "scales": np.asarray(scales, dtype=np.float32),
            "quats": np.asarray(quats, dtype=np.float32),
            "opacities": np.asarray(opacities, dtype=np.float32).reshape(-1),
            "sh": np.asarray(sh, dtype=np.float16 if np.asarray(sh).dtype == np.float16 else np.float32),
        }
        if filter_3d is not None:
            arrays["filter_3d"] = np.asarray(filter_3d, dtype=np.float32).reshape(-1)
        if view_weight_sh is not None:
            vw = np.asarray(view_weight_sh, dtype=np.float32)
            arrays["view_weight_sh"] = vw.reshape(len(vw), -1) if vw.ndim != 2 else vw
        if arrays["sh"].ndim == 2:
            arrays["sh"] = arrays["sh"][:, None, :]
        n = check_shapes(arrays, source)
        if "view_weight_sh" in arrays:
            vw = arrays["view_weight_sh"]
            if vw.shape[0] != n:
                raise GBViewerError(f"{source}: field 'view_weight_sh': shape {vw.shape}, expected ({n}, K)")
            sh_degree_for(vw.shape[1])
        for name, val in (("wsr_sigma", wsr_sigma), ("weight_background", weight_background), ("et_grade", et_grade)):
            if val is not None and not (np.isfinite(val) and (val >= 0 if name == "weight_background" else val > 0)):
                raise GBViewerError(
                    f"{source}: {name} = {val!r}; expected a finite number "
                    + (">= 0" if name == "weight_background" else "> 0")
                )
        if n == 0:
            raise GBViewerError(f"{source}: the scene has zero splats")

        if checked is None:
            finite = _valid_rows(arrays, n)
        elif checked.keep.shape == (n,) and checked.keep.dtype == bool:
            finite = checked.keep
        else:
            raise GBViewerError(
                f"{source}: checked.keep is {checked.keep.dtype} {checked.keep.shape}; expected bool ({n},)"
            )
        dropped = int(n - finite.sum())
        if dropped:
            why = f"non-finite values (or scales over {MAX_SCALE:g}, SH over {MAX_SH:g})"
            if dropped == n:
                raise GBViewerError(f"{source}: every splat has {why}")
            warnings.warn(f"{source}: dropped {dropped} of {n} splats with {why}", stacklevel=2)
            arrays = {k: v[finite] for k, v in arrays.items()}
            if cells is not None:  # renumber the members, drop the removed splats from their cells
                cells = Cells.from_groups(
                    cells.means,
                    cells.scales,
                    cells.quats,
                    cells.cell_of(n)[finite],
                    cells.origin,
                    cells.build_ms,
                    cells.info,
                )

        if checked is None:
            if (arrays["scales"] < 0).any():
                raise GBViewerError(f"{source}: field 'scales': negative values; expected activated scales >= 0")
            arrays["quats"] = unit_quats(arrays["quats"])
            arrays["opacities"] = np.clip(arrays["opacities"], 0.0, 1.0)
            if "filter_3d" in arrays:
                arrays["filter_3d"] = np.abs(arrays["filter_3d"])
        arrays = {k: np.ascontiguousarray(v) for k, v in arrays.items()}
        if cells is not None:
            if len(cells.members) and (cells.members.min() < 0 or cells.members.max() >= len(arrays["means"])):
                raise GBViewerError(f"{source}: field 'cells': member indices outside 0..{len(arrays['means']) - 1}")
        globals_ = {"sigma": wsr_sigma, "weight_background": weight_background, "et_grade": et_grade}
        globals_ = {k: None if v is None else float(v) for k, v in globals_.items()}
        vw = arrays.pop("view_weight_sh", None)
        oit = OitData(vw, cells=cells, neural=neural, **globals_)
        if vw is None and cells is None and neural is None and all(v is None for v in globals_.values()):
            oit = None
        return cls(source=source, meta=dict(meta or {}), oit=oit, **arrays)


def check_shapes(arrays: dict[str, np.ndarray], source: str) -> int:
    """The splat count of a Scene's arrays by name, whose shapes must be (N, 3) means and scales, (N, 4) quats, (N,)
    opacities and filter_3d, (N, K, 3) sh of a K that is an SH degree's; else a one-line GBViewerError."""
    means = arrays["means"]
    n = means.shape[0] if means.ndim == 2 else -1
    expected = {"means": (n, 3), "scales": (n, 3), "quats": (n, 4), "opacities": (n,), "filter_3d": (n,)}
    for name, shape in expected.items():
        if arrays.get(name) is not None and arrays[name].shape != shape:
            raise GBViewerError(f"{source}: field '{name}': shape {arrays[name].shape}, expected {shape}")
    sh = arrays["sh"]
    if sh.ndim != 3 or sh.shape[0] != n or sh.shape[2] != 3:
        raise GBViewerError(f"{source}: field 'sh': shape {sh.shape}, expected ({n}, K, 3)")
    sh_degree_for(sh.shape[1])
    return n


def loaded_from(scene: Scene, content: str | None) -> Scene:
    """`scene` with `content` the digest of the bytes it came from (gbviewer.load)."""
    object.__setattr__(scene, "content", content)
    return scene


def _valid_rows(arrays: dict[str, np.ndarray], n: int) -> np.ndarray:
    """(n,) bool: the splats whose values in every array are finite and within LIMITS."""
    finite = np.ones(n, dtype=bool)
    for arr in arrays.values():
        # A finite sum proves every element finite (NaN and inf propagate); the per-splat reduction is only
        # needed when it is not (or when a float32 sum of finite values overflowed).
        with np.errstate(over="ignore", invalid="ignore"):
            total = arr.sum(dtype=np.float32)  # float16 SH: summed in float32
        if not np.isfinite(total):
            finite &= np.isfinite(arr.reshape(n, -1)).all(axis=1)
    for name, limit in LIMITS.items():
        arr = arrays.get(name)
        flat = arr.reshape(-1) if arr is not None else None
        # fmax / fmin skip NaN (dropped above) and reduce without a temporary the size of the array
        if flat is not None and max(np.fmax.reduce(flat), -np.fmin.reduce(flat)) > np.float32(limit):
            finite &= ~(np.abs(arr) > np.float32(limit)).reshape(n, -1).any(axis=1)
    return finite


def _norms(q: np.ndarray) -> np.ndarray:
    """|q| per row of (M, 4) float32, summed as (w^2 + x^2) + (y^2 + z^2): numpy's einsum order, and the native
    loader's (gbviewer._native.io), so that both normalise to the same bits."""
    with np.errstate(over="ignore", invalid="ignore"):
        sq = q * q
        return np.sqrt((sq[:, 0] + sq[:, 1]) + (sq[:, 2] + sq[:, 3]))


def unit_quats(quats: np.ndarray) -> np.ndarray:
    """A normalised float32 copy of (N, 4) quaternions: rows within 4 float32 eps of unit length kept as they are
    (so loading is idempotent), the others divided by their norm; norms under 1e-12 give the identity."""
    q = np.array(quats, dtype=np.float32)  # a contiguous copy, normalised in place
    norm = _norms(q)
    big = np.isinf(norm)  # components near the float32 maximum, whose squares overflow: scaled down first
    if big.any():
        q[big] /= np.abs(q[big]).max(axis=1, keepdims=True)
        norm[big] = _norms(q[big])
    fix = np.abs(norm - 1) > 4 * np.finfo(np.float32).eps
    if fix.any():
        degenerate = norm < 1e-12
        q[fix] /= np.maximum(norm[fix], 1e-12)[:, None]
        q[degenerate] = (1.0, 0.0, 0.0, 0.0)
    return q
