"""Hand-written glTF splat files for the tests: accessors of any allowed component type (normalised integers
quantised here by glTF's own rule), strides, sparse substitutions, node hierarchies; written as .glb, or .gltf with
an embedded (data URI) or external buffer. Independent of gbviewer's writer."""

from __future__ import annotations

import base64
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

EXT = "KHR_gaussian_splatting"
P = EXT + ":"
DTYPES = {5120: "i1", 5121: "u1", 5122: "<i2", 5123: "<u2", 5125: "<u4", 5126: "<f4"}
NORM = {5120: 127, 5121: 255, 5122: 32767, 5123: 65535}
TYPES = {1: "SCALAR", 3: "VEC3", 4: "VEC4"}


def quantise(values: np.ndarray, ctype: int, normalized: bool) -> tuple[np.ndarray, np.ndarray]:
    """Stored values and what glTF says they decode to (normalised: c / max, at least -1)."""
    if ctype == 5126:
        stored = np.asarray(values, "<f4")
        return stored, stored.astype(np.float32)
    scale = NORM[ctype] if normalized else 1
    stored = np.round(np.asarray(values, np.float64) * scale).astype(DTYPES[ctype])
    decoded = stored.astype(np.float32)
    return stored, np.maximum(decoded / np.float32(scale), -1) if normalized else decoded


@dataclass
class GltfFile:
    """A glTF document under construction: one BIN buffer of bufferViews."""

    bin: bytearray = field(default_factory=bytearray)
    doc: dict = field(
        default_factory=lambda: {
            "asset": {"version": "2.0"},
            "extensionsUsed": [EXT],
            "accessors": [],
            "bufferViews": [],
            "meshes": [],
            "nodes": [],
        }
    )

    def view(self, data: bytes, stride: int = 0) -> int:
        self.bin += b"\0" * (-len(self.bin) % 4)
        v = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if stride:
            v["byteStride"] = stride
        self.bin += data
        self.doc["bufferViews"].append(v)
        return len(self.doc["bufferViews"]) - 1

    def accessor(
        self,
        values: np.ndarray,
        ctype: int = 5126,
        normalized: bool = False,
        stride: int = 0,
        sparse: tuple[np.ndarray, np.ndarray] | None = None,
        no_view: bool = False,
    ) -> int:
        """An accessor of (N, width) `values` (already of `ctype`); `stride` pads each element, `sparse`
        (rows, values) adds a substitution, `no_view` leaves the base all zeros."""
        values = np.asarray(values, DTYPES[ctype]).reshape(len(values), -1)
        n, width = values.shape
        acc = {"componentType": ctype, "count": n, "type": TYPES[width]}
        if normalized:
            acc["normalized"] = True
        if not no_view:
            elem = values.itemsize * width
            if stride:
                rows = np.zeros((n, stride), np.uint8)
                rows[:, :elem] = values.view(np.uint8).reshape(n, elem)
                acc["bufferView"] = self.view(rows.tobytes(), stride)
            else:
                acc["bufferView"] = self.view(values.tobytes())
        if sparse is not None:
            rows, sub = sparse
            acc["sparse"] = {
                "count": len(rows),
                "indices": {"bufferView": self.view(np.asarray(rows, "<u2").tobytes()), "componentType": 5123},
                "values": {"bufferView": self.view(np.asarray(sub, DTYPES[ctype]).tobytes())},
            }
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def primitive(self, attributes: dict[str, int], props: dict | None = None, mode: int = 0) -> dict:
        return {"mode": mode, "attributes": attributes, "extensions": {EXT: props or {"kernel": "ellipse"}}}

    def mesh(self, *primitives: dict) -> int:
        self.doc["meshes"].append({"primitives": list(primitives)})
        return len(self.doc["meshes"]) - 1

    def node(self, **node) -> int:
        self.doc["nodes"].append(node)
        return len(self.doc["nodes"]) - 1

    def splats(self, s: dict, sh_degree: int | None = None) -> dict:
        """A float primitive of splats `s` (means, scales, quats (w,x,y,z), opacities, sh) in glTF's axes."""
        attrs = {
            "POSITION": self.accessor(s["means"]),
            P + "ROTATION": self.accessor(np.concatenate([s["quats"][:, 1:], s["quats"][:, :1]], 1)),
            P + "SCALE": self.accessor(s["scales"]),
            P + "OPACITY": self.accessor(s["opacities"]),
        }
        k = s["sh"].shape[1] if sh_degree is None else (sh_degree + 1) ** 2
        names = [f"SH_DEGREE_{d}_COEF_{i}" for d in range(4) for i in range(2 * d + 1)]
        attrs.update({P + names[i]: self.accessor(s["sh"][:, i]) for i in range(k)})
        return self.primitive(attrs)

    def write(self, path: Path, how: str = "glb") -> Path:
        """As a .glb ("glb"), or a .gltf with its buffer in a data URI ("embedded") or a file beside it."""
        doc = dict(self.doc, buffers=[{"byteLength": len(self.bin)}])
        if "scenes" not in doc:
            doc["scenes"], doc["scene"] = (
                [
                    {
                        "nodes": [
                            i
                            for i in range(len(doc["nodes"]))
                            if not any(i in n.get("children", []) for n in doc["nodes"])
                        ]
                    }
                ],
                0,
            )
        if how == "embedded":
            doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(self.bin).decode()
        elif how == "external":
            (path.parent / (path.stem + ".bin")).write_bytes(bytes(self.bin))
            doc["buffers"][0]["uri"] = path.stem + ".bin"
        text = json.dumps(doc).encode()
        if how != "glb":
            path.write_bytes(text)
            return path
        text += b" " * (-len(text) % 4)
        binary = bytes(self.bin) + b"\0" * (-len(self.bin) % 4)
        body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(binary), 0x004E4942) + binary
        path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
        return path
