"""Trained-like synthetic scenes of any size for scaling benchmarks.

Dense, small, mostly opaque splats lying flat on surfaces (a ground plane with fine stripes, a sphere with a
fine checker), plus thin wires and a fence of thin posts: the structures that alias when zoomed out.
Deterministic for a given (n, seed). Up axis is +z.

    python bench/synthetic.py 1000000 out.ply      # write an INRIA .ply
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

import gbviewer as gb
from gbviewer.model.scene import SH_C0


def _frame_quats(normals: np.ndarray) -> np.ndarray:
    """Unit quaternions (w,x,y,z) rotating +z onto each normal (splats flat on the surface)."""
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, normals)
    s = np.linalg.norm(axis, axis=1, keepdims=True)
    c = normals @ z
    angle = np.arctan2(s[:, 0], c)
    axis = np.where(s > 1e-9, axis / np.maximum(s, 1e-12), [1.0, 0.0, 0.0])
    return np.concatenate([np.cos(angle / 2)[:, None], axis * np.sin(angle / 2)[:, None]], axis=1)


def make_scene(n: int, seed: int = 0) -> gb.Scene:
    """n splats: 60% plane, 28% sphere, 8% wires, 4% fence posts. Spacing adapts to n so surfaces stay covered."""
    rng = np.random.default_rng(seed)
    n_plane, n_sphere, n_wire = int(0.60 * n), int(0.28 * n), int(0.08 * n)
    n_post = n - n_plane - n_sphere - n_wire

    # ground plane z = 0 over [-1, 1]^2, stripes of period 0.04 along x
    side = int(np.ceil(np.sqrt(max(n_plane, 1))))
    spacing = 2.0 / side
    cell = np.arange(n_plane)  # jittered grid: covered like a trained surface, no random gaps
    jitter = rng.uniform(-0.3, 0.3, (n_plane, 2)) * spacing
    p = np.column_stack(
        [
            -1 + (cell % side + 0.5) * spacing + jitter[:, 0],
            -1 + (cell // side + 0.5) * spacing + jitter[:, 1],
            np.zeros(n_plane),
        ]
    )
    p_scale = np.column_stack(
        [np.full(n_plane, spacing * 0.7), np.full(n_plane, spacing * 0.7), np.full(n_plane, spacing * 0.05)]
    )
    stripe = (np.floor(p[:, 0] / 0.02) % 2)[:, None]
    p_col = stripe * [0.9, 0.85, 0.75] + (1 - stripe) * [0.15, 0.2, 0.3]
    p_normal = np.tile([0.0, 0.0, 1.0], (n_plane, 1))

    # sphere of radius 0.45 resting on the plane, fine latitude/longitude checker
    v = rng.normal(size=(n_sphere, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    s = v * 0.45 + [0.0, 0.0, 0.45]
    sp = np.sqrt(4 * np.pi * 0.45**2 / max(n_sphere, 1))
    s_scale = np.column_stack([np.full(n_sphere, sp * 0.7), np.full(n_sphere, sp * 0.7), np.full(n_sphere, sp * 0.05)])
    lat, lon = np.arcsin(np.clip(v[:, 2], -1, 1)), np.arctan2(v[:, 1], v[:, 0])
    check = ((np.floor(lat / 0.05) + np.floor(lon / 0.05)) % 2)[:, None]
    s_col = check * [0.8, 0.2, 0.15] + (1 - check) * [0.95, 0.9, 0.85]

    # 12 thin orange horizontal wires at z = 1.1, diameter ~ 2 mm, across the scene
    k = np.arange(n_wire) % 12
    t = rng.uniform(-1, 1, n_wire)
    w = np.column_stack([t, -0.9 + 0.15 * k, np.full(n_wire, 1.1)])
    w_scale = np.column_stack(
        [np.full(n_wire, 2.4 / max(n_wire / 12, 1)), np.full(n_wire, 0.001), np.full(n_wire, 0.001)]
    )
    w_col = np.tile([1.0, 0.6, 0.1], (n_wire, 1))
    w_normal = np.tile([0.0, 0.0, 1.0], (n_wire, 1))

    # fence: 40 thin vertical posts along y = 0.9
    kp = np.arange(n_post) % 40
    f = np.column_stack([-0.975 + 0.05 * kp, np.full(n_post, 0.9), rng.uniform(0, 0.6, n_post)])
    f_scale = np.column_stack(
        [np.full(n_post, 0.004), np.full(n_post, 0.004), np.full(n_post, 0.6 * 40 / max(n_post, 1))]
    )
    f_col = np.tile([0.9, 0.9, 0.95], (n_post, 1))
    f_normal = np.tile([0.0, 0.0, 1.0], (n_post, 1))

    means = np.concatenate([p, s, w, f])
    scales = np.concatenate([p_scale, s_scale, w_scale, f_scale])
    quats = np.concatenate([_frame_quats(p_normal), _frame_quats(v), _frame_quats(w_normal), _frame_quats(f_normal)])
    colors = np.concatenate([p_col, s_col, w_col, f_col]) + rng.normal(0, 0.02, (n, 3))
    opacities = np.clip(rng.normal(0.95, 0.05, n), 0.3, 0.999)
    sh = ((colors - 0.5) / SH_C0)[:, None, :]
    return gb.Scene.from_arrays(
        means, scales, quats, opacities, sh, source=f"synthetic-{n}", meta={"format": "synthetic", "version": None}
    )


def main(argv: list[str]) -> int:
    if len(argv) != 2:
        print(__doc__)
        return 2
    from gbviewer.io.write import write_inria_ply

    scene = make_scene(int(float(argv[0])))
    write_inria_ply(scene, Path(argv[1]))
    print(f"wrote {argv[1]}: {scene.num_splats} splats")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
