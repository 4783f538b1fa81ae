"""A training-style dataset made of a scene's own dense renders, so that `gbviewer eval` measures every mode's
fidelity at each sampling rate against the dense reference on a scene that comes without its photos:

    python bench/dense_dataset.py SCENE OUT_DIR [--views 4] [--size 320x240] [--reference supersample:8]
    gbviewer eval SCENE --data OUT_DIR --split all --rates 1,1/2,1/4,1/8 --modes ... --plots PLOTS

OUT_DIR gets a 3DGS cameras.json (orbit views spread in azimuth, elevation 20 degrees, the default framing) and
images/vNN.png, the reference render of each view on black (8-bit). At rate 1/k eval's ground truth is that image
box-downsampled by k, i.e. the reference at 1/k with k x k times its samples: the zoom-out fidelity of the bench's
fidelity table, through eval's tables and plots."""

from __future__ import annotations

import json
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
if any((REPO / "gbviewer").glob("_native*")):  # the checkout's build, else the installed package
    sys.path.insert(0, str(REPO))

import gbviewer as gb  # noqa: E402 (after the sys.path choice above)
from gbviewer.cli.argtypes import SIZE, Parser, count  # noqa: E402 (after the sys.path choice above)
from gbviewer.outputs.figure import save_image  # noqa: E402 (after the sys.path choice above)

ELEVATION = 20.0


def write_dataset(
    scene_path: Path, out: Path, views: int, size: tuple[int, int], reference: str, up: str = "-y"
) -> Path:
    """cameras.json and images/ in `out` (see the module's docstring); returns the cameras.json."""
    scene = gb.load(scene_path)
    settings = gb.RenderSettings.parse(reference)
    entries = []
    for k in range(views):
        cam = gb.orbit_camera(scene, 360.0 * k / views, ELEVATION, width=size[0], height=size[1], up=up)
        name = f"v{k:02d}"
        save_image(out / "images" / f"{name}.png", gb.render(scene, cam, settings).rgb, force=True)
        centre = -cam.R.T @ cam.t
        entries.append(
            {
                "id": k,
                "img_name": name,
                "width": cam.width,
                "height": cam.height,
                "fx": cam.fx,
                "fy": cam.fy,
                "rotation": cam.R.T.tolist(),
                "position": centre.tolist(),
            }
        )
    path = out / "cameras.json"
    path.write_text(json.dumps(entries, indent=1))
    return path


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scene", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--views", type=count(360), default=4, help="orbit views (default 4)")
    ap.add_argument("--size", type=SIZE, default=(320, 240), metavar="WxH", help="image size (default 320x240)")
    ap.add_argument("--reference", default="supersample:8", help="the dense mode rendered (default supersample:8)")
    ap.add_argument("--up", default="-y", choices=["-y", "+y", "+z", "-z"])
    args = ap.parse_args(argv)
    print(f"wrote {write_dataset(args.scene, args.out, args.views, args.size, args.reference, args.up)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
