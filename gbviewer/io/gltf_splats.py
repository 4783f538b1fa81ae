"""Gaussian splats in glTF: `KHR_gaussian_splatting` POINTS primitives, plain or `KHR_gaussian_splatting_compression_
spz_2` (KhronosGroup/glTF extensions/2.0/Khronos/KHR_gaussian_splatting/README.md and ..._compression_spz_2).

Attributes: POSITION, `:ROTATION` (x, y, z, w), `:SCALE` (linear), `:OPACITY` (after the sigmoid),
`:SH_DEGREE_d_COEF_n` (RGB; the 3DGS basis, DC the colour's (c - 0.5) / SH_C0), optional COLOR_0 (the DC where no
SH_DEGREE_0_COEF_0 is given). Every node that instantiates a splat mesh applies its world transform (TRS or matrix,
through its parents). glTF's frame (+X left, +Y up, +Z forward; splat-transform's Transform.PLY in
playcanvas/splat-transform src/lib/utils/math.ts) is the INRIA/COLMAP frame (x right, y down, z forward) turned
180 degrees about z: x and y negate, so do the quaternion's x and y and the SH coefficients odd in x or y. An SPZ
stream in glTF is stored in glTF's axes (LUF, as that extension requires).
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..model.cells import rotation_matrices
from ..model.scene import SH_C0, Scene
from .gltf import FLOAT, UBYTE, USHORT, Gltf, read_gltf
from .packing import MAX_SPLATS
from .progress import LoadProgress
from .spz import FLIP_SH as SPZ_FLIP_SH
from .spz import FLIP_XYZ as SPZ_FLIP_XYZ
from .spz import load_spz
from .trained_as import COMMENT_KEY
from .transform import apply_matrix

EXT = "KHR_gaussian_splatting"
SPZ_EXT = "KHR_gaussian_splatting_compression_spz_2"
PREFIX = EXT + ":"
POINTS = 0
SUPPORTED = {
    "kernel": ("ellipse",),
    "projection": ("perspective",),
    "sortingMethod": ("cameraDistance",),
    "colorSpace": ("srgb_rec709_display",),
}
DEFAULTS = {
    "kernel": "ellipse",
    "projection": "perspective",
    "sortingMethod": "cameraDistance",
    "colorSpace": "srgb_rec709_display",
}
FLIP_XYZ = np.array([-1.0, -1.0, 1.0], np.float32)  # glTF <-> INRIA: 180 degrees about z
# Sign of each SH coefficient (degree 1..3, 3DGS basis order) under (x, y, z) -> (-x, -y, z).
FLIP_SH = np.array([-1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1, 1, -1], np.float32)
QUAT_FLIP = np.array([1.0, -1.0, -1.0, 1.0], np.float32)  # (w, x, y, z) of the same turn
# Component types each attribute may use (the extension's attribute table; POSITION as KHR_mesh_quantization).
ALLOWED = {
    "POSITION": {
        FLOAT: (False,),
        5120: (False, True),
        UBYTE: (False, True),
        5122: (False, True),
        USHORT: (False, True),
    },
    "ROTATION": {FLOAT: (False,), 5120: (True,), 5122: (True,)},
    "SCALE": {FLOAT: (False,), 5120: (False, True), 5122: (False, True)},
    "OPACITY": {FLOAT: (False,), UBYTE: (True,), USHORT: (True,)},
    "SH": {FLOAT: (False,)},
    "COLOR_0": {FLOAT: (False,), UBYTE: (True,), USHORT: (True,)},
}
SH_PER_DEGREE = (1, 3, 5, 7)


def load_gltf(path: Path, progress: LoadProgress, primitive: int | None = None) -> Scene:
    """Every splat primitive a scene node instantiates (or only the `primitive`-th), as one Scene."""
    gl = read_gltf(path, progress)
    instances = _instances(gl)
    if not instances:
        raise gl.error(f"no mesh primitive with the {EXT} extension")
    if primitive is not None:
        if not 0 <= primitive < len(instances):
            raise gl.error(
                f"--primitive {primitive}: the file has {len(instances)} splat primitives (0..{len(instances) - 1})"
            )
        instances = [instances[primitive]]
    budget = gl.size  # each splat needs data somewhere
    parts, exts, total = [], [], 0
    for prim, matrix, where in instances:
        arrays, ext = _decode(gl, prim, where)
        total += len(arrays[0])
        if total > min(MAX_SPLATS, budget):
            raise gl.error(f"{total} splats in all; more than the file's {budget} bytes can describe", where)
        if not np.array_equal(matrix, np.eye(4)):
            means, scales, quats, sh = apply_matrix(matrix, *arrays[:3], arrays[4])
            arrays = (means, scales, quats, arrays[3], sh)
        parts.append(arrays)
        exts.append(ext)
        progress.check()
    means, scales, quats, opacities, sh = _join(gl, parts)
    degree = (sh.shape[1] > 1) + (sh.shape[1] > 4) + (sh.shape[1] > 9)
    sh[:, 1:] *= FLIP_SH[: sh.shape[1] - 1, None]
    meta = {
        "format": "glb" if gl.glb else "gltf",
        "version": "2.0",
        "properties": sorted({k for p, _, _ in instances for k in p.get("attributes", {})}),
        "compression": "spz_2" if any(SPZ_EXT in e.get("extensions", {}) for e in exts) else None,
        "primitives": len(instances),
        "sh_degree_stored": degree,
    }
    meta.update(_properties(path, exts))
    extras = gl.doc["asset"].get("extras")
    if isinstance(extras, dict) and isinstance(extras.get(COMMENT_KEY), str):
        meta["splat_render_mode"] = extras[COMMENT_KEY]
    if len(instances) > 1:
        meta["note"] = f"{len(instances)} splat primitives loaded as one scene (--primitive N loads the N-th alone)"
        warnings.warn(f"{path}: {meta['note']}", stacklevel=3)
    return Scene.from_arrays(means * FLIP_XYZ, scales, quats * QUAT_FLIP, opacities, sh, source=str(path), meta=meta)


def _properties(path: Path, exts: list[dict]) -> dict:
    """kernel, projection, sortingMethod and colorSpace (the first primitive's; a value unsupported here or
    differing between primitives is said in one warning line each)."""
    out = {}
    for key, default in DEFAULTS.items():
        values = list(dict.fromkeys(str(e.get(key, default)) for e in exts))
        out[key] = values[0] if len(values) == 1 else values
        odd = [v for v in values if v not in SUPPORTED[key]]
        if odd:
            warnings.warn(
                f"{path}: {EXT} {key} {', '.join(odd)} is not supported; rendered as {SUPPORTED[key][0]}", stacklevel=4
            )
    return out


def _instances(gl: Gltf) -> list[tuple[dict, np.ndarray, str]]:
    """(primitive, world matrix, where) for each splat primitive each node of the scene instantiates, in order;
    without nodes that do, every splat primitive of every mesh in place."""
    doc = gl.doc
    scenes = doc.get("scenes")
    nodes = doc.get("nodes", [])
    if not isinstance(nodes, list):
        raise gl.error("expected a list", "nodes")
    if isinstance(scenes, list) and scenes:
        scene = gl.element("scenes", doc.get("scene", 0), "scene")
        roots = scene.get("nodes", [])
    else:
        children = {c for n in nodes if isinstance(n, dict) for c in n.get("children", []) if isinstance(c, int)}
        roots = [i for i in range(len(nodes)) if i not in children]
    if not isinstance(roots, list):
        raise gl.error("expected a list of node indices", "scene.nodes")
    out: list[tuple[dict, np.ndarray, str]] = []
    seen: set[int] = set()
    stack = [(r, np.eye(4), "scene.nodes") for r in reversed(roots)]
    while stack:
        index, parent, where = stack.pop()
        node = gl.element("nodes", index, where)
        if index in seen:
            raise gl.error("a node reached twice (node graphs must be trees)", f"nodes[{index}]")
        seen.add(index)
        world = parent @ _local(gl, node, index)
        if "mesh" in node:
            out += [(p, world, w) for p, w in _splat_primitives(gl, node["mesh"], f"nodes[{index}].mesh")]
        kids = node.get("children", [])
        if not isinstance(kids, list):
            raise gl.error("expected a list", f"nodes[{index}].children")
        stack += [(k, world, f"nodes[{index}].children") for k in reversed(kids)]
    if not out:
        meshes = doc.get("meshes", [])
        for m in range(len(meshes) if isinstance(meshes, list) else 0):
            out += [(p, np.eye(4), w) for p, w in _splat_primitives(gl, m, "meshes")]
    return out


def _splat_primitives(gl: Gltf, mesh_index: object, where: str) -> list[tuple[dict, str]]:
    mesh = gl.element("meshes", mesh_index, where)
    prims = mesh.get("primitives", [])
    if not isinstance(prims, list):
        raise gl.error("expected a list", f"meshes[{mesh_index}].primitives")
    out = []
    for i, p in enumerate(prims):
        name = f"meshes[{mesh_index}].primitives[{i}]"
        if isinstance(p, dict) and isinstance(p.get("extensions"), dict) and EXT in p["extensions"]:
            if p.get("mode", 4) != POINTS:
                raise gl.error(f"mode {p.get('mode', 4)!r}; a splat primitive must be POINTS (0)", name)
            if not isinstance(p["extensions"][EXT], dict) or not isinstance(p.get("attributes", {}), dict):
                raise gl.error(f"{EXT} and attributes must be objects", name)
            out.append((p, name))
    return out


def _local(gl: Gltf, node: dict, index: int) -> np.ndarray:
    """A node's local matrix: `matrix` (column-major) or T R S."""
    where = f"nodes[{index}]"
    if "matrix" in node:
        m = _numbers(gl, node["matrix"], 16, f"{where}.matrix")
        return m.reshape(4, 4).T
    t = _numbers(gl, node.get("translation", [0, 0, 0]), 3, f"{where}.translation")
    x, y, z, w = _numbers(gl, node.get("rotation", [0, 0, 0, 1]), 4, f"{where}.rotation")
    s = _numbers(gl, node.get("scale", [1, 1, 1]), 3, f"{where}.scale")
    q = np.array([w, x, y, z])
    norm = np.linalg.norm(q)
    if norm == 0:
        raise gl.error("a zero quaternion", f"{where}.rotation")
    m = np.eye(4)
    m[:3, :3] = rotation_matrices((q / norm)[None])[0] * s
    m[:3, 3] = t
    return m


def _numbers(gl: Gltf, v: object, n: int, where: str) -> np.ndarray:
    if (
        not isinstance(v, list)
        or len(v) != n
        or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v)
    ):
        raise gl.error(f"expected {n} numbers", where)
    return np.array(v, np.float64)


def _decode(gl: Gltf, prim: dict, where: str) -> tuple[tuple, dict]:
    """(means, scales, quats (w,x,y,z), opacities, sh) in glTF's frame, and the primitive's extension object."""
    ext = prim["extensions"][EXT]
    compressed = ext.get("extensions", {}).get(SPZ_EXT) if isinstance(ext.get("extensions"), dict) else None
    if compressed is not None:
        return _decode_spz(gl, prim, compressed, where), ext
    attrs = prim.get("attributes", {})

    def read(name: str, width: int, kind: str, count: int | None) -> np.ndarray:
        return gl.accessor(attrs[name], f"{where}.attributes.{name}", width, ALLOWED[kind], count)

    for name in ("POSITION", PREFIX + "ROTATION", PREFIX + "SCALE", PREFIX + "OPACITY"):
        if name not in attrs:
            raise gl.error(f"missing attribute {name}", f"{where}.attributes")
    means = read("POSITION", 3, "POSITION", None)
    n = len(means)
    if n == 0:
        raise gl.error("zero splats", f"{where}.attributes.POSITION")
    xyzw = read(PREFIX + "ROTATION", 4, "ROTATION", n)
    scales = read(PREFIX + "SCALE", 3, "SCALE", n)
    opacities = read(PREFIX + "OPACITY", 1, "OPACITY", n)[:, 0]
    coeffs = [_dc(gl, attrs, read, n, where)]
    given = []
    for degree in (1, 2, 3):
        names = [f"{PREFIX}SH_DEGREE_{degree}_COEF_{i}" for i in range(SH_PER_DEGREE[degree])]
        present = sum(name in attrs for name in names)
        if present not in (0, len(names)):
            raise gl.error(
                f"SH degree {degree} is partly given ({present} of {len(names)} coefficients)", f"{where}.attributes"
            )
        given.append(names if present else None)
    if None in given and any(given[given.index(None) :]):
        raise gl.error(f"SH degree {given.index(None) + 1} is missing below a higher degree", f"{where}.attributes")
    coeffs += [read(name, 3, "SH", n) for names in given if names for name in names]
    quats = np.concatenate([xyzw[:, 3:], xyzw[:, :3]], axis=1)
    return (means, scales, quats, opacities, np.stack(coeffs, axis=1)), ext


def _dc(gl: Gltf, attrs: dict, read, n: int, where: str) -> np.ndarray:
    """SH_DEGREE_0_COEF_0, or the DC that COLOR_0's RGB (0.5 + SH_C0 dc) gives where it is absent."""
    if PREFIX + "SH_DEGREE_0_COEF_0" in attrs:
        return read(PREFIX + "SH_DEGREE_0_COEF_0", 3, "SH", n)
    if "COLOR_0" not in attrs:
        raise gl.error(f"neither {PREFIX}SH_DEGREE_0_COEF_0 nor COLOR_0: no colour", f"{where}.attributes")
    kind = gl.element("accessors", attrs["COLOR_0"], f"{where}.attributes.COLOR_0").get("type")
    rgb = read("COLOR_0", 4 if kind == "VEC4" else 3, "COLOR_0", n)[:, :3]
    return (rgb - np.float32(0.5)) / np.float32(SH_C0)


def _decode_spz(gl: Gltf, prim: dict, compressed: object, where: str) -> tuple:
    """The SPZ stream of `KHR_gaussian_splatting_compression_spz_2`, back in glTF's frame (our SPZ reader turns
    SPZ's RUB into the INRIA frame; the stream here is in glTF's axes, so that turn is undone)."""
    if not isinstance(compressed, dict):
        raise gl.error("expected an object", f"{where}.{SPZ_EXT}")
    data, _ = gl.view_bytes(compressed.get("bufferView"), f"{where}.{SPZ_EXT}.bufferView")
    scene = load_spz(gl.path, bytes(data))
    n = scene.num_splats
    position = prim.get("attributes", {}).get("POSITION")
    if position is not None:
        count = gl.element("accessors", position, f"{where}.attributes.POSITION").get("count")
        if count != n:
            raise gl.error(f"POSITION count {count!r}; the SPZ stream holds {n} splats", where)
    sh = scene.sh.copy()
    sh[:, 1:] *= SPZ_FLIP_SH[: sh.shape[1] - 1, None]
    flip_q = np.concatenate([[1.0], SPZ_FLIP_XYZ]).astype(np.float32)
    return scene.means * SPZ_FLIP_XYZ, scene.scales, scene.quats * flip_q, scene.opacities, sh


def _join(gl: Gltf, parts: list[tuple]) -> tuple:
    """Primitives' arrays concatenated; SH padded with zeros to the highest degree among them."""
    k = max(p[4].shape[1] for p in parts)
    out = [np.concatenate([p[i] for p in parts]).astype(np.float32) for i in range(4)]
    sh = np.concatenate([np.pad(p[4], ((0, 0), (0, k - p[4].shape[1]), (0, 0))) for p in parts]).astype(np.float32)
    return (*out, sh)
