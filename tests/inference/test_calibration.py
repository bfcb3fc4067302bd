"""Camera calibration: a known installed padel camera is recovered from noisy clicked points."""
from __future__ import annotations

import numpy as np
import pytest

from inference.camera.calibration import CalibrationError, calibrate, calibrate_court, dlt
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


def test_floor_points_alone_recover_the_camera(padel):
    """Only floor points (corners, service lines, net ends): focal length and pose from the plane."""
    true = installed_padel_camera()
    ground = {n: p for n, p in clicked_points(true, padel, 1.0).items() if padel.points[n][2] == 0}
    assert len(ground) >= 8
    result = calibrate_court(padel, ground, (W, H))
    assert result.method == "plane"
    assert np.linalg.norm(result.camera.centre - true.centre) < 0.15
    assert abs(result.camera.K[0, 0] / true.K[0, 0] - 1) < 0.02
    np.testing.assert_allclose(result.camera.K[:2, 2], [W / 2, H / 2])
    assert result.rms_px < 1.5
    # the uncertainty is honest: the true centre lies within a few sigma, and sigma is small but not zero
    sigma = result.centre_sigma_m
    assert np.all(sigma > 0) and np.linalg.norm(sigma) < 0.2
    assert np.all(np.abs(result.camera.centre - true.centre) < 5 * sigma + 0.02)
    assert result.warnings == []


@pytest.mark.parametrize("fov", [25.0, 50.0, 75.0])
def test_floor_points_exact_for_any_focal_length(padel, fov):
    true = Camera.from_look_at(eye=[3.0, -7.0, 8.0], target=[5.5, 10.0, 0.0], image_size=(1920, 1080), fov_deg=fov)
    names = ["near_left", "near_right", "far_left", "far_right", "near_service_center", "far_service_center",
             "net_left", "net_right"]
    pts = dict(zip(names, true.project(padel.point_array(names))))
    result = calibrate_court(padel, pts, (1920, 1080))
    assert np.linalg.norm(result.camera.centre - true.centre) < 1e-4
    assert abs(result.camera.K[0, 0] - true.K[0, 0]) < 1e-3


def test_floor_points_with_radial_distortion_on_request(padel):
    true = Camera.from_krt(installed_padel_camera().K, installed_padel_camera().R, installed_padel_camera().t,
                           (W, H), dist=[-0.15, 0, 0, 0, 0])
    ground = {n: p for n, p in clicked_points(true, padel, 0.3).items() if padel.points[n][2] == 0}
    plain = calibrate_court(padel, ground, (W, H))
    fitted = calibrate_court(padel, ground, (W, H), n_dist=1)
    assert fitted.rms_px < 0.6 < plain.rms_px
    assert abs(fitted.camera.dist[0] + 0.15) < 0.03
    assert np.linalg.norm(fitted.camera.centre - true.centre) < 0.2
    # the plain fit says what its RMS means (its pose covariance cannot hold a lens model that does not fit)
    assert plain.rms_px > 2.0 and any("--distortion" in w for w in plain.warnings), plain.warnings
    assert not any("--distortion" in w for w in fitted.warnings)
    assert fitted.camera.pose_covariance() is not None and fitted.camera.meta["pose_cov"]


def test_camera_looking_straight_down_is_flagged(padel):
    true = Camera.from_look_at(eye=[5.0, 10.0, 25.0], target=[5.0, 10.01, 0.0], image_size=(W, H), fov_deg=60)
    ground = {n: p for n, p in clicked_points(true, padel, 1.0).items() if padel.points[n][2] == 0}
    result = calibrate_court(padel, ground, (W, H))
    assert any("straight at the plane" in w for w in result.warnings)
    assert "warning:" in result.table()


def test_points_in_a_small_part_of_the_image_are_flagged(padel):
    true = Camera.from_look_at(eye=[5.0, -30.0, 12.0], target=[5.0, 10.0, 0.0], image_size=(W, H), fov_deg=50)
    ground = {n: p for n, p in clicked_points(true, padel, 0.5).items() if padel.points[n][2] == 0}
    result = calibrate_court(padel, ground, (W, H))
    assert any("cover only" in w for w in result.warnings)


def test_off_plane_points_cannot_buy_a_far_principal_point(padel):
    """Floor points plus three net-top points, one of them clicked badly: the prior keeps the principal
    point near the centre, where the free DLT lets it wander."""
    true = Camera.from_look_at(eye=[5.0, -6.0, 8.0], target=[5.0, 10.0, 0.0], image_size=(1920, 1080), fov_deg=55)
    names = ["near_left", "near_right", "far_left", "far_right", "near_service_left", "near_service_center",
             "near_service_right", "far_service_left", "far_service_center", "far_service_right", "net_left",
             "net_right", "net_post_left_top", "net_center_top", "net_post_right_top"]
    rng = np.random.default_rng(3)
    pts = {n: xy + rng.uniform(-3, 3, 2) for n, xy in zip(names, true.project(padel.point_array(names)))}
    pts["net_center_top"] = pts["net_center_top"] + np.array([0.0, 8.0])  # the net sags: clicked low
    free = calibrate_court(padel, pts, (1920, 1080), principal_point="free")
    prior = calibrate_court(padel, pts, (1920, 1080))
    pp_err = lambda r: np.linalg.norm(r.camera.K[:2, 2] - [960, 540])  # noqa: E731
    assert pp_err(free) > 100 and pp_err(prior) < 20
    assert np.linalg.norm(prior.camera.centre - true.centre) < 0.1 < np.linalg.norm(free.camera.centre - true.centre)
    assert prior.method == "general"


def test_well_supported_off_centre_principal_point_is_kept(padel):
    """Many accurate off-plane points do show a principal point 40 px off the centre: the prior lets it."""
    base = Camera.from_look_at(eye=[5.0, -3.0, 6.0], target=[5.0, 9.0, 0.0], image_size=(W, H), fov_deg=80)
    K = base.K.copy()
    K[:2, 2] += [40.0, -30.0]
    true = Camera.from_krt(K, base.R, base.t, (W, H))
    pts = clicked_points(true, padel, noise_px=0.3, seed=1)
    result = calibrate_court(padel, pts, (W, H))
    np.testing.assert_allclose(result.camera.K[:2, 2], K[:2, 2], atol=8.0)
    assert np.linalg.norm(result.camera.centre - true.centre) < 0.05


def test_collinear_points_raise_clear_error(padel):
    true = installed_padel_camera()
    names = ["near_service_left", "near_service_center", "near_service_right", "net_left", "net_center",
             "net_right"]
    line = {n: xy for n, xy in zip(names, true.project(padel.point_array(names)))}
    line = {n: xy for n, xy in line.items() if n.startswith("net")}
    line.update({f"{n}": true.project(padel.points[n][None])[0] for n in ["far_left", "far_right"]})
    collinear = {n: true.project(padel.points[n][None])[0]
                 for n in ["near_left", "near_right", "far_left", "far_right"]}
    with pytest.raises(CalibrationError, match="at least 6"):
        calibrate_court(padel, collinear, (W, H))
    along = {n: true.project(padel.points[n][None])[0] for n in
             ["near_left", "near_service_left", "net_left", "far_service_left", "far_left", "step_near_left_end_ground"]}
    with pytest.raises(CalibrationError, match="lie on one line") as e:
        calibrate_court(padel, along, (W, H))
    assert "net_post_left_top" in str(e.value)


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


def _club_camera(seed: int) -> Camera:
    """A club's wide-angle court camera: high behind the near glass, 100° across 1920×1080, barrel k1 −0.3…−0.6."""
    rng = np.random.default_rng(seed)
    return Camera.from_look_at(eye=[5.0 + rng.uniform(-0.5, 0.5), -1.0 + rng.uniform(-1, 0.5), 6.5 + rng.uniform(-1, 1)],
                               target=[5.0, 8.5 + rng.uniform(-1, 1), 0.0], image_size=(1920, 1080), fov_deg=100,
                               dist=np.array([rng.uniform(-0.6, -0.3), 0, 0, 0, 0]))


CLUB_POINTS = ["near_service_left", "near_service_right", "far_service_left", "far_service_right", "net_left",
               "net_right", "far_left", "far_right"]


def _along_side_lines(cam: Camera, court, rng) -> list:
    out = []
    for a, b in (("near_left", "far_left"), ("near_right", "far_right")):
        for s in np.linspace(0.1, 0.9, 6):
            out.append((a, b, cam.project((court.points[a] + s * (court.points[b] - court.points[a]))[None])[0]
                        + rng.uniform(-1.5, 1.5, 2)))
    return out


def test_points_along_the_bent_side_lines_pin_a_wide_angle_lens(padel):
    """Eight floor points of a club camera (k1 −0.3…−0.6) plus six clicks along each side line, which the lens
    bends: camera centre within 0.1 m, focal within 1 %, k1 within 0.02 on every one of three cameras; a click
    put on the wrong line is flagged."""
    for seed in range(3):
        cam, rng = _club_camera(seed), np.random.default_rng(100 + seed)
        pts = {n: cam.project(padel.points[n][None])[0] + rng.uniform(-1.5, 1.5, 2) for n in CLUB_POINTS}
        r = calibrate_court(padel, pts, (1920, 1080), n_dist=1, line_points=_along_side_lines(cam, padel, rng))
        assert np.linalg.norm(r.camera.centre - cam.centre) < 0.1, seed
        assert abs(r.camera.K[0, 0] / cam.K[0, 0] - 1) < 0.01 and abs(r.camera.dist[0] - cam.dist[0]) < 0.02, seed
        assert not any("along court lines" in w for w in r.warnings)
    lines = _along_side_lines(cam, padel, rng)
    lines[5] = ("near_left", "near_right", lines[5][2])  # a click far up the side line filed under the baseline
    r = calibrate_court(padel, pts, (1920, 1080), n_dist=1, line_points=lines)
    assert any("points along court lines lie off their line" in w for w in r.warnings)
