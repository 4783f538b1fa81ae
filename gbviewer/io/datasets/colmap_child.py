"""Run as a script by `colmap.read_colmap` in a child process: `colmap_child.py FOLDER MAX_BYTES` reads the COLMAP
model in FOLDER with pycolmap and prints its cameras and posed images as JSON (floats written exactly; NaN and
Infinity as Python writes them, for the parent to name). pycolmap's readers can loop forever or abort on a
malformed file: the parent bounds this process's time, and it limits its own address space to MAX_BYTES, or keeps
the lower limit it was started under (a malformed count fails to allocate). Imports nothing of gbviewer."""

from __future__ import annotations

import json
import resource
import sys


def describe(folder: str) -> dict:
    import pycolmap

    rec = pycolmap.Reconstruction()
    rec.read(folder)
    cameras = {
        str(cid): {
            "model": c.model_name,
            "width": c.width,
            "height": c.height,
            "params": [float(p) for p in c.params],
            "names": [n.strip() for n in c.params_info.split(",")],
        }
        for cid, c in rec.cameras.items()
    }
    images = []
    for image in rec.images.values():
        if not image.has_pose:
            continue
        pose = image.cam_from_world()
        images.append(
            {
                "name": image.name,
                "camera": str(image.camera_id),
                "q": [float(v) for v in pose.rotation.quat],
                "R": pose.rotation.matrix().tolist(),
                "t": pose.translation.tolist(),
            }
        )
    return {"cameras": cameras, "images": images}


def limit_memory(limit: int) -> None:
    """At most `limit` bytes of address space, never more than the limit already in force (which cannot be
    raised)."""
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    current = min(v for v in (soft, hard, limit) if v != resource.RLIM_INFINITY)
    resource.setrlimit(resource.RLIMIT_AS, (current, current))


if __name__ == "__main__":
    limit_memory(int(sys.argv[2]))
    try:
        doc = describe(sys.argv[1])
    except Exception as exc:  # noqa: BLE001 (pycolmap raises ValueError, IndexError, MemoryError, ... for bad files)
        doc = {"error": f"{type(exc).__name__}: {' '.join(str(exc).split())}"}
    json.dump(doc, sys.stdout)
