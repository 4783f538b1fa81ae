"""What a pane shows of a frame (colour or a debug plane: alpha, transmittance, Gaussian Blending's window size,
evaluations per pixel, false-coloured with viridis) and the 16-bit PNG of a pane's render. The difference, error and
photo views need more than the frame: `analysis.PaneAnalysis` makes them (here they show the frame's colour)."""

from __future__ import annotations

import struct
import zlib

import numpy as np

VIEWS = ("color", "alpha", "transmittance", "window", "evals", "difference", "error", "photo", "flicker")
VIEW_HELP = {
    "color": "the image",
    "alpha": "accumulated alpha (1 - final transmittance), black 0 to white 1",
    "transmittance": "final transmittance T, black 0 to white 1",
    "window": "Gaussian Blending's final window size per pixel (sqrt(w*h), output pixels), viridis 0..max",
    "evals": "splats evaluated per pixel, viridis 0..max",
    "difference": "this pane minus pane A (mean over RGB; blue: darker, red: brighter), colour bar in the pane",
    "error": "this pane minus the reference chosen in 'Difference and error' (box-downsampled x1, dense 8x8 or the "
    "photo)",
    "photo": "the snapped dataset view's photo at the rate (box-downsampled, alpha-aware) instead of the render",
    "flicker": "heat map of this pane's flicker over a 0.1 degree orbit step from here, against scalar 8x8 "
    "(gbviewer flicker)",
}

_VIRIDIS = np.array(
    [
        [0.267, 0.005, 0.329],
        [0.283, 0.141, 0.458],
        [0.254, 0.265, 0.530],
        [0.207, 0.372, 0.553],
        [0.164, 0.471, 0.558],
        [0.128, 0.567, 0.551],
        [0.135, 0.659, 0.518],
        [0.267, 0.749, 0.441],
        [0.478, 0.821, 0.318],
        [0.741, 0.873, 0.150],
        [0.993, 0.906, 0.144],
    ],
    np.float32,
)


def viridis(x: np.ndarray) -> np.ndarray:
    """Values in [0, 1] to RGB (an 11-point approximation of matplotlib's viridis)."""
    x = np.clip(np.nan_to_num(np.asarray(x, np.float32)), 0, 1) * (len(_VIRIDIS) - 1)
    i = np.minimum(x.astype(np.int32), len(_VIRIDIS) - 2)
    t = (x - i)[..., None]
    return _VIRIDIS[i] * (1 - t) + _VIRIDIS[i + 1] * t


def visualize(frame, view: str) -> tuple[np.ndarray, str]:
    """The RGB image (H, W, 3 float in [0, 1]) a pane shows for `view`, and a legend ('' for colour).

    'window' falls back to colour (saying so) when the frame has no window plane (modes other than
    gaussian_blending)."""
    if view == "alpha":
        a = np.clip(frame.alpha, 0, 1)
        return np.repeat(a[..., None], 3, axis=2), "alpha 0..1"
    if view == "transmittance":
        t = np.clip(1 - frame.alpha, 0, 1)
        return np.repeat(t[..., None], 3, axis=2), "transmittance 0..1"
    if view == "evals":
        ev = np.asarray(frame.debug.get("evals", np.zeros(frame.alpha.shape)), np.float32)
        top = max(1.0, float(ev.max()))
        return viridis(ev / top), f"evaluations/pixel 0..{top:.0f}"
    if view == "window":
        win = frame.debug.get("window")
        if win is None:
            return frame.rgb, "window: gaussian_blending only"
        size = np.sqrt(np.maximum(win[..., 0], 0) * np.maximum(win[..., 1], 0))
        top = max(1e-6, float(size.max()))
        return viridis(size / top), f"window size 0..{top:.2f} px"
    return frame.rgb, ""


def encode_png16(rgb: np.ndarray) -> bytes:
    """A 16-bit-per-channel RGB PNG of a float image in [0, 1] (clipped): a pane's render at full precision."""
    img = np.clip(np.nan_to_num(np.asarray(rgb, np.float64)), 0, 1)
    h, w = img.shape[:2]
    data = np.round(img[..., :3] * 65535).astype(">u2")
    raw = b"".join(b"\x00" + data[r].tobytes() for r in range(h))

    def chunk(tag: bytes, body: bytes) -> bytes:
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)

    header = struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def decode_png16(data: bytes) -> np.ndarray:
    """Inverse of encode_png16 (unfiltered rows only): (H, W, 3) uint16."""
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        tag, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + n]
        if tag == b"IHDR":
            w, h = struct.unpack(">II", body[:8])
        elif tag == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    rows = np.frombuffer(raw, np.uint8).reshape(h, 1 + w * 6)
    return rows[:, 1:].copy().view(">u2").reshape(h, w, 3).astype(np.uint16)
