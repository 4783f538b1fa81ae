"""Write a Scene as a `.glb` with `KHR_gaussian_splatting` (the inverse of gbviewer.io.gltf_splats), in the layout
PlayCanvas SplatTransform writes (playcanvas/splat-transform src/lib/writers/write-glb.ts): one node, one POINTS
primitive, float attributes, a COLOR_0 fallback; axes turned into glTF's (exact sign flips).

Plain: lossless (float32 as stored; loading gives back the scene bit for bit). With `spz`: the attributes come from
one SPZ v3 stream in a bufferView (`KHR_gaussian_splatting_compression_spz_2`, in glTF's axes), within SPZ's
precision (gbviewer.io.write_packed); its accessors have no bufferView, as that extension describes.
The training mode, where known, goes in `asset.extras` as {"SplatRenderMode": "mip" | "default"}, the PLY comment's
convention (gbviewer.io.trained_as).
"""

from __future__ import annotations

import json
import struct

import numpy as np

from ..model.scene import SH_C0, Scene
from .gltf import BIN_CHUNK, FLOAT, GLB_HEADER, GLB_MAGIC, JSON_CHUNK, UBYTE
from .gltf_splats import EXT, FLIP_SH, FLIP_XYZ, PREFIX, QUAT_FLIP, SH_PER_DEGREE, SPZ_EXT
from .trained_as import COMMENT_KEY, WRITTEN
from .write_packed import antialiased_mode, spz_bytes, u8

ARRAY_BUFFER = 34962


def _pad(data: bytes, fill: bytes) -> bytes:
    return data + fill * (-len(data) % 4)


def gltf_arrays(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """means, scales, quats (w,x,y,z), opacities and SH in glTF's axes."""
    sh = np.array(scene.sh, np.float32)
    sh[:, 1:] *= FLIP_SH[: sh.shape[1] - 1, None]
    return scene.means * FLIP_XYZ, scene.scales, scene.quats * QUAT_FLIP, scene.opacities, sh


def glb_bytes(scene: Scene, spz: bool = False) -> bytes:
    """The whole `.glb` file."""
    means, scales, quats, opacities, sh = gltf_arrays(scene)
    n = len(means)
    names = ["POSITION", "COLOR_0", PREFIX + "ROTATION", PREFIX + "SCALE", PREFIX + "OPACITY"]
    names += [f"{PREFIX}SH_DEGREE_{d}_COEF_{i}" for d in range(4) for i in range(SH_PER_DEGREE[d])][: sh.shape[1]]
    rgba = np.concatenate(
        [u8((0.5 + SH_C0 * sh[:, 0].astype(np.float64)) * 255), u8(opacities.astype(np.float64) * 255)[:, None]], axis=1
    )
    columns = [means, rgba, np.concatenate([quats[:, 1:], quats[:, :1]], axis=1), scales, opacities[:, None]]
    columns += [sh[:, i] for i in range(sh.shape[1])]
    accessors, views, blobs, offset = [], [], [], 0
    for name, col in zip(names, columns):
        acc = {
            "componentType": UBYTE if col.dtype == np.uint8 else FLOAT,
            "count": n,
            "type": {1: "SCALAR", 3: "VEC3", 4: "VEC4"}[col.shape[1]],
        }
        if col.dtype == np.uint8:
            acc["normalized"] = True
        if name == "POSITION":
            acc["min"], acc["max"] = col.min(axis=0).tolist(), col.max(axis=0).tolist()
        if not spz:
            data = np.ascontiguousarray(col, "u1" if col.dtype == np.uint8 else "<f4").tobytes()
            acc["bufferView"] = len(views)
            views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(data), "target": ARRAY_BUFFER})
            blobs.append(_pad(data, b"\0"))
            offset += len(blobs[-1])
        accessors.append(acc)
    ext: dict = {
        "kernel": "ellipse",
        "colorSpace": "srgb_rec709_display",
        "sortingMethod": "cameraDistance",
        "projection": "perspective",
    }
    used = [EXT]
    if spz:
        stream = spz_bytes(means, scales, quats, opacities, sh, antialiased_mode(scene))
        ext["extensions"] = {SPZ_EXT: {"bufferView": 0}}
        views.append({"buffer": 0, "byteOffset": 0, "byteLength": len(stream)})
        blobs.append(_pad(stream, b"\0"))
        used.append(SPZ_EXT)
    asset: dict = {"version": "2.0", "generator": "gbviewer"}
    mode = WRITTEN.get(scene.meta.get("trained_as", ""))
    if mode:
        asset["extras"] = {COMMENT_KEY: mode}
    doc = {
        "asset": asset,
        "extensionsUsed": used,
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [
            {"primitives": [{"mode": 0, "attributes": {k: i for i, k in enumerate(names)}, "extensions": {EXT: ext}}]}
        ],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": sum(map(len, blobs))}],
    }
    if spz:
        doc["extensionsRequired"] = used
    body = _pad(json.dumps(doc, separators=(",", ":")).encode(), b" ")
    binary = b"".join(blobs)
    chunks = struct.pack("<II", len(body), JSON_CHUNK) + body + struct.pack("<II", len(binary), BIN_CHUNK) + binary
    return GLB_HEADER.pack(GLB_MAGIC, 2, GLB_HEADER.size + len(chunks)) + chunks
