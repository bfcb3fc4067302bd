"""Camera calibration: a known installed padel camera is recovered from noisy clicked points."""
from __future__ import annotations

import numpy as np
import pytest

from inference.calibration import CalibrationError, calibrate, calibrate_court, dlt
from inference.camera import Camera
from inference.court import load_court

W, H = 1280, 720


def installed_padel_camera() -> Camera:
    """A typical installed camera: 6 m high, 3 m behind the near back glass, looking down the court."""
    return Camera.from_look_at(eye=[5.0, -3.0, 6.0], target=[5.0, 9.0, 0.0], image_size=(W, H), fov_deg=80)


def clicked_points(cam: Camera, court, noise_px: float, seed: int = 0) -> dict[str, np.ndarray]:
    """Project every court point, keep those inside the image, add uniform ±noise_px clicking noise."""
    rng = np.random.default_rng(seed)
    px = cam.project(court.point_array(court.point_names))
    inside = (px[:, 0] >= 0) & (px[:, 0] < W) & (px[:, 1] >= 0) & (px[:, 1] < H)
    return {n: px[i] + rng.uniform(-noise_px, noise_px, 2) for i, n in enumerate(court.point_names) if inside[i]}


@pytest.fixture(scope="module")
def padel():
    return load_court("padel")


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("model", ["square", "pinhole"])
def test_installed_camera_recovered_from_noisy_clicks(padel, seed, model):
    true = installed_padel_camera()
    pts = clicked_points(true, padel, noise_px=1.0, seed=seed)
    assert len(pts) >= 20
    result = calibrate_court(padel, pts, (W, H), model=model)
    assert np.linalg.norm(result.camera.centre - true.centre) < 0.1
    assert result.rms_px < 1.5
    assert set(result.residuals_px) == set(pts)
    # the recovered camera reprojects unseen 3D points (a ball 1.5 m over the far service line) well
    X = np.array([[2.0, 16.0, 1.5], [8.0, 5.0, 2.5]])
    assert np.abs(result.camera.project(X) - true.project(X)).max() < 3.0


def test_minimal_off_ground_set(padel):
    """Four ground corners + service centres + two net-post tops: 8 points, not coplanar."""
    true = Camera.from_look_at(eye=[5.0, -6.0, 7.0], target=[5.0, 10.0, 0.0], image_size=(W, H), fov_deg=70)
    names = ["near_left", "near_right", "far_left", "far_right", "near_service_center",
             "far_service_center", "net_post_left_top", "net_post_right_top"]
    pts = dict(zip(names, true.project(padel.point_array(names))))
    result = calibrate_court(padel, pts, (W, H))
    assert np.linalg.norm(result.camera.centre - true.centre) < 1e-3
    assert result.rms_px < 1e-3


def test_coplanar_points_raise_clear_error(padel):
    true = installed_padel_camera()
    ground = {n: p for n, p in clicked_points(true, padel, 0.5).items() if padel.points[n][2] == 0}
    assert len(ground) >= 6
    with pytest.raises(CalibrationError, match="all lie on one plane") as e:
        calibrate_court(padel, ground, (W, H))
    msg = str(e.value)
    assert "net_post_left_top" in msg and "off-ground" in msg


def test_too_few_points(padel):
    true = installed_padel_camera()
    pts = dict(list(clicked_points(true, padel, 0.0).items())[:4])
    with pytest.raises(CalibrationError, match="4 court points given.*at least 6"):
        calibrate_court(padel, pts, (W, H))


def test_unknown_point_name(padel):
    with pytest.raises(KeyError, match="unknown point 'net_top_middle'.*net_center_top"):
        calibrate_court(padel, {"net_top_middle": (1.0, 2.0)}, (W, H))


def test_wrong_click_is_flagged(padel):
    true = installed_padel_camera()
    pts = clicked_points(true, padel, 0.5)
    pts["net_post_left_top"] = pts["net_post_left_top"] + np.array([40.0, -25.0])
    result = calibrate_court(padel, pts, (W, H))
    assert result.suspect == ["net_post_left_top"]
    assert "check this click" in result.table()


def test_non_finite_input():
    world = np.random.default_rng(0).uniform(0, 5, (8, 3))
    img = np.ones((8, 2))
    img[3, 0] = np.nan
    with pytest.raises(CalibrationError, match="non-finite"):
        calibrate(world, img, (W, H))


def test_dlt_exact_on_noiseless_general_camera():
    K = np.array([[900.0, 2.0, 600.0], [0, 950.0, 380.0], [0, 0, 1]])
    cam = Camera.from_krt(K, installed_padel_camera().R, installed_padel_camera().t, (W, H))
    world = np.random.default_rng(3).uniform([0, 0, 0], [10, 20, 3], (12, 3))
    P = dlt(world, cam.project(world))
    est = Camera(P=P, image_size=(W, H))
    np.testing.assert_allclose(est.K, K, rtol=1e-6, atol=1e-4)
    np.testing.assert_allclose(est.centre, cam.centre, atol=1e-6)


def test_radial_distortion_fit(padel):
    K = installed_padel_camera().K
    true = Camera.from_krt(K, installed_padel_camera().R, installed_padel_camera().t, (W, H),
                           dist=[-0.12, 0.02, 0, 0, 0])
    pts = clicked_points(true, padel, noise_px=0.3)
    plain = calibrate_court(padel, pts, (W, H))
    fitted = calibrate_court(padel, pts, (W, H), n_dist=2)
    assert fitted.rms_px < 0.5 < plain.rms_px
    assert np.linalg.norm(fitted.camera.centre - true.centre) < 0.1
