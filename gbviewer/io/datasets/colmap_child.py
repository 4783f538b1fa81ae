"""Run as a script by `colmap.read_colmap` in a child process: `colmap_child.py FOLDER MAX_BYTES` reads the COLMAP
model in FOLDER with pycolmap and prints its cameras and posed images as JSON (floats written exactly). pycolmap's
readers can loop forever or abort on a malformed file: the parent bounds this process's time, and it limits its
own address space to MAX_BYTES (a malformed count fails to allocate). Imports nothing of gbviewer."""

from __future__ import annotations

import json
import resource
import sys


def describe(folder: str) -> dict:
    import pycolmap

    rec = pycolmap.Reconstruction()
    rec.read(folder)
    cameras = {str(cid): {"model": c.model_name, "width": c.width, "height": c.height,
                          "params": [float(p) for p in c.params],
                          "names": [n.strip() for n in c.params_info.split(",")]}
               for cid, c in rec.cameras.items()}
    images = []
    for image in rec.images.values():
        if not image.has_pose:
            continue
        pose = image.cam_from_world()
        images.append({"name": image.name, "camera": str(image.camera_id),
                       "R": pose.rotation.matrix().tolist(), "t": pose.translation.tolist()})
    return {"cameras": cameras, "images": images}


if __name__ == "__main__":
    resource.setrlimit(resource.RLIMIT_AS, (int(sys.argv[2]), int(sys.argv[2])))
    try:
        doc = describe(sys.argv[1])
    except Exception as exc:  # pycolmap raises ValueError, IndexError, MemoryError, ... for bad files
        doc = {"error": f"{type(exc).__name__}: {' '.join(str(exc).split())}"}
    json.dump(doc, sys.stdout)
