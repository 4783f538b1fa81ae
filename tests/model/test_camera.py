import json

import numpy as np
import pytest

import gbviewer as gb
from gbviewer.model.camera import UP_AXES, orbit_camera


def project(cam: gb.Camera, p: np.ndarray) -> np.ndarray:
    x = cam.R @ p + cam.t
    return np.array([cam.fx * x[0] / x[2] + cam.cx, cam.fy * x[1] / x[2] + cam.cy])


def rot(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = axis / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def test_sampling_rate_keeps_the_view():
    cam = gb.Camera(640, 480, 500, 510, 320, 240, rot(np.array([1.0, 2, 3]), 0.4), [0.1, -0.2, 3])
    p = np.array([0.3, -0.1, 0.5])
    for s in (8, 2, 0.5, 1 / 8):
        c = cam.at_sampling_rate(s)
        assert (c.width, c.height) == (round(640 * s), round(480 * s))
        np.testing.assert_allclose(project(c, p), project(cam, p) * s, rtol=1e-9)
    with pytest.raises(gb.CameraError):
        cam.at_sampling_rate(0)


def test_cameras_json_round_trip(tmp_path):
    R_w2c = rot(np.array([0.2, 1.0, -0.4]), 1.1)
    centre = np.array([1.0, -2.0, 0.5])
    entry = {
        "id": 0,
        "img_name": "00001",
        "width": 800,
        "height": 600,
        "position": centre.tolist(),
        "rotation": R_w2c.T.tolist(),
        "fx": 700.0,
        "fy": 710.0,
    }
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([entry]))
    (cam,) = gb.load_cameras_json(path)
    np.testing.assert_allclose(cam.R, R_w2c, atol=1e-12)
    np.testing.assert_allclose(cam.position, centre, atol=1e-12)
    assert (cam.width, cam.height, cam.fx, cam.fy, cam.cx, cam.cy) == (800, 600, 700.0, 710.0, 400.0, 300.0)
    # a point straight ahead of the camera projects to the image centre
    ahead = centre + 3.0 * R_w2c[2]
    np.testing.assert_allclose(project(cam, ahead), [400, 300], atol=1e-9)


@pytest.mark.parametrize(
    "bad",
    [
        [],
        [{"width": 10}],
        [
            {
                "width": 10,
                "height": 10,
                "fx": 5,
                "fy": 5,
                "position": [0, 0, 0],
                "rotation": [[2, 0, 0], [0, 1, 0], [0, 0, 1]],
            }
        ],
    ],
)
def test_cameras_json_errors_name_the_file(tmp_path, bad):
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps(bad))
    with pytest.raises(gb.CameraError, match="cameras.json"):
        gb.load_cameras_json(path)


def test_look_at_axes():
    cam = gb.Camera.look_at(np.array([0.0, 0, -5]), np.zeros(3), up=(0, -1, 0))
    np.testing.assert_allclose(cam.R @ cam.R.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(cam.R) == pytest.approx(1.0)
    # world -y is up, so a point above the target appears above the image centre (smaller row)
    assert project(cam, np.array([0.0, -1, 0]))[1] < cam.cy
    assert project(cam, np.zeros(3)) == pytest.approx([cam.cx, cam.cy])


def test_default_camera_ignores_stray_splats():
    rng = np.random.default_rng(1)
    n = 2000
    means = rng.uniform(-1, 1, (n, 3))
    base = dict(
        scales=np.full((n, 3), 0.01),
        quats=np.tile([1.0, 0, 0, 0], (n, 1)),
        opacities=np.full(n, 0.5),
        sh=np.zeros((n, 1, 3)),
    )
    scene = gb.Scene.from_arrays(means, **base)
    stray = means.copy()
    stray[:10] = rng.uniform(-1, 1, (10, 3)) * 1000.0  # 0.5% of splats far away
    scene_stray = gb.Scene.from_arrays(stray, **base)
    c1, c2 = orbit_camera(scene), orbit_camera(scene_stray)
    assert np.linalg.norm(c1.position - c2.position) < 0.1 * np.linalg.norm(c1.position)
    # the scene fills a good part of the view: the robust box corners project inside the image
    lo, hi = scene.robust_bounds()
    for corner in np.array(np.meshgrid(*zip(lo, hi))).T.reshape(-1, 3):
        x, y = project(c1, corner)
        assert -0.05 * c1.width <= x <= 1.05 * c1.width and -0.05 * c1.height <= y <= 1.05 * c1.height


def test_invalid_cameras_raise():
    with pytest.raises(gb.CameraError):
        gb.Camera(0, 10, 1, 1, 0, 0, np.eye(3), np.zeros(3))
    with pytest.raises(gb.CameraError):
        gb.Camera(10, 10, float("nan"), 1, 0, 0, np.eye(3), np.zeros(3))
    with pytest.raises(gb.CameraError):
        gb.Camera(10, 10, 1, 1, 0, 0, np.eye(3) * 2, np.zeros(3))


@pytest.mark.parametrize(
    "kwargs, says",
    [
        ({"width": 0, "height": 5}, "orbit width: expected >= 1"),
        ({"height": 0}, "orbit height: expected >= 1"),
        ({"fov_y_deg": 0}, "orbit field of view"),
        ({"elevation_deg": float("inf")}, "orbit elevation"),
        ({"azimuth_deg": "x"}, "orbit azimuth"),
    ],
)
def test_orbit_camera_arguments_are_one_line(bundled_scene, kwargs, says):
    """A zero height or field of view divided by zero (ZeroDivisionError), an infinite elevation failed in math."""
    with pytest.raises(gb.CameraError, match=says):
        orbit_camera(bundled_scene, **kwargs)


def test_a_camera_holds_its_own_read_only_pose():
    """Camera kept the caller's float64 R and t: editing them afterwards moved the camera (unchecked: R need not stay
    a rotation) and changed its hash while it was a key. It holds read-only copies."""
    R, t = np.eye(3), np.zeros(3)
    cam = gb.Camera(10, 10, 5, 5, 5, 5, R, t)
    key = hash(cam)
    R[0, 0], t[0] = 2.0, 1.0
    assert cam.R[0, 0] == 1.0 and cam.t[0] == 0.0 and hash(cam) == key
    with pytest.raises(ValueError, match="read-only"):
        cam.R[0, 0] = 2.0


def test_rate_labels_and_parsing():
    from gbviewer.model.camera import format_rate, parse_rate, parse_rates

    assert [format_rate(r) for r in (8, 1, 0.125, 0.27, 2.5)] == ["x8", "x1", "x1/8", "x1/3.7", "x2.5"]
    assert parse_rate(" 1/8") == parse_rate("0.125") == 0.125 and parse_rates("4,1, 1/2") == [4.0, 1.0, 0.5]
    for bad in ("0", "-1", "x", "1/0"):
        with pytest.raises(gb.GBViewerError, match="sampling rate"):
            parse_rate(bad)
    with pytest.raises(gb.GBViewerError, match="empty item"):  # no rate, or an empty one among them
        parse_rates(" , ")


def test_focal_length_and_field_of_view_agree():
    from gbviewer.model.camera import focal_from_fov, fov_of

    cam = gb.Camera.look_at([0, 0, -3], [0, 0, 0], width=64, height=48, fov_y_deg=60)
    assert cam.fy == pytest.approx(focal_from_fov(60, 48)) and fov_of(cam) == pytest.approx(60)


def test_orbit_framing_sees_the_whole_box():
    from gbviewer.model.camera import frame_box, orbit_direction

    lo, hi = np.array([-1.0, -2.0, 0.0]), np.array([1.0, 2.0, 4.0])
    centre, radius, dist = frame_box(lo, hi, 50.0, 4 / 3)
    assert np.allclose(centre, [0, 0, 2]) and radius == pytest.approx(3.0)
    assert radius / dist == pytest.approx(np.sin(np.radians(25)) / 0.9)  # the bounding sphere fills 90% of the view
    up = np.array(UP_AXES["-y"])
    d = orbit_direction(up, 30.0, 20.0)
    assert np.linalg.norm(d) == pytest.approx(1) and float(d @ up) == pytest.approx(np.sin(np.radians(20)))


def project_any(cam: gb.Camera, p: np.ndarray) -> np.ndarray:
    """Pixel position of world points (N, 3) under either projection."""
    x = p @ cam.R.T + cam.t
    z = 1.0 if cam.orthographic else x[:, 2]
    return np.c_[cam.fx * x[:, 0] / z + cam.cx, cam.fy * x[:, 1] / z + cam.cy]


def test_orthographic_camera():
    """fx, fy in pixels per unit: a point's pixel does not depend on its depth; zoom (sampling rate, size) scales
    them; with_projection keeps things at the given depth the same size; bad projections are refused."""
    persp = gb.Camera(640, 480, 500, 510, 320, 240, rot(np.array([1.0, 2, 3]), 0.4), [0.1, -0.2, 3])
    ortho = persp.with_projection("orthographic", 4.0)
    assert ortho.orthographic and ortho.projection_code == 1 and (ortho.fx, ortho.fy) == (125.0, 127.5)
    assert ortho.with_projection("perspective", 4.0) == persp and persp.with_projection("perspective", -1) is persp
    p_cam = np.array([[0.3, -0.1, 4.0], [0.3, -0.1, 9.0]])
    p = (p_cam - persp.t) @ persp.R  # world points at depths 4 and 9, same x, y in the camera
    np.testing.assert_allclose(project_any(ortho, p), project_any(persp, p[:1]).repeat(2, 0), rtol=1e-9)
    for s in (8, 1 / 8):
        c = ortho.at_sampling_rate(s)
        assert c.orthographic
        np.testing.assert_allclose(project_any(c, p), project_any(ortho, p) * s, rtol=1e-9)
    assert ortho.with_size(320, 240).fx == 62.5
    dirs, dist = ortho.view_rays(p)
    np.testing.assert_allclose(dirs, np.tile(persp.R[2], (2, 1)), atol=1e-12)
    np.testing.assert_allclose(dist, [4.0, 9.0])
    dirs, dist = persp.view_rays(p)
    np.testing.assert_allclose(dirs * dist[:, None], p - persp.position, atol=1e-12)
    with pytest.raises(gb.CameraError, match="projection: expected perspective or orthographic, got 'fisheye'"):
        gb.Camera(10, 10, 1, 1, 0, 0, np.eye(3), np.zeros(3), projection="fisheye")
    with pytest.raises(gb.CameraError, match="depth"):
        persp.with_projection("orthographic", 0.0)


def test_orthographic_orbit_frames_the_scene_like_the_perspective_one(bundled_scene):
    """The orthographic orbit stands at the same eye with f / distance pixels per unit: the plane through the orbit
    centre keeps its scale, and the scene's robust box spans about as much of the image as in perspective."""
    persp = orbit_camera(bundled_scene, 30, 20, width=160, height=120)
    ortho = orbit_camera(bundled_scene, 30, 20, width=160, height=120, projection="orthographic")
    lo, hi = bundled_scene.robust_bounds()
    centre = (np.asarray(lo, np.float64) + hi) / 2
    distance = float(np.linalg.norm(persp.position - centre))
    np.testing.assert_allclose(ortho.position, persp.position, atol=1e-9)
    assert ortho.orthographic and ortho.fy == pytest.approx(persp.fy / distance)
    corners = np.array(np.meshgrid(*zip(lo, hi))).T.reshape(-1, 3)
    spans = [np.ptp(project_any(c, corners), axis=0) for c in (persp, ortho)]
    assert np.all((spans[1] > 0.7 * spans[0]) & (spans[1] < 1.3 * spans[0])), spans
    alpha = [gb.render(bundled_scene, c, "scalar").alpha for c in (persp, ortho)]
    coverage = [(a > 0.5).mean() for a in alpha]
    assert 0.1 < coverage[1] and 0.7 < coverage[1] / coverage[0] < 1.3, coverage


def test_cameras_json_projection(tmp_path):
    entry = {"width": 80, "height": 60, "position": [0, 0, -5], "rotation": np.eye(3).tolist(), "fx": 20.0, "fy": 20.0}
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps([entry, dict(entry, projection="orthographic"), dict(entry, projection="perspective")]))
    assert [c.projection for c in gb.load_cameras_json(path)] == ["perspective", "orthographic", "perspective"]
    path.write_text(json.dumps([entry, dict(entry, projection=3)]))
    with pytest.raises(
        gb.CameraError, match="cameras.json: entry 1: 'projection': expected perspective or orthographic, got '3'"
    ):
        gb.load_cameras_json(path)


def test_robust_bounds_are_the_percentiles_over_the_splats(bundled_scene):
    """Column by column, the very values np.percentile gives over axis 0 (the framing of every camera rests on them),
    on the bundled scene and on spread, clustered and repeated coordinates."""
    rng = np.random.default_rng(5)
    cases = [
        bundled_scene.means,
        rng.normal(0, 1e3, (1001, 3)),
        np.round(rng.normal(0, 2, (999, 3))),
        np.concatenate([rng.uniform(-1, 1, (500, 3)), np.full((7, 3), 1e30)]),
    ]
    for means in cases:
        scene = gb.Scene.from_arrays(
            means.astype(np.float32),
            np.full((len(means), 3), 0.1, np.float32),
            np.tile(np.float32([1, 0, 0, 0]), (len(means), 1)),
            np.full(len(means), 0.5, np.float32),
            np.zeros((len(means), 1, 3), np.float32),
        )
        for pct in (2.0, 0.0, 37.5):
            want = np.percentile(scene.means.astype(np.float64), [pct, 100 - pct], axis=0).astype(np.float32)
            got = scene.robust_bounds(pct)
            assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
