"""Camera projection, rays, camera.yaml round trip and errors; ray/plane intersections with extents."""
from __future__ import annotations

import numpy as np
import pytest

from inference.camera import Camera, decompose_projection
from inference.clipio.errors import FormatError
from inference.court import load_court
from inference.court.geometry import intersect_event, intersect_plane, intersect_planes

W, H = 1280, 720


@pytest.fixture(scope="module")
def padel():
    return load_court("padel")


@pytest.fixture(scope="module")
def cam():
    return Camera.from_look_at(eye=[5.0, -3.0, 6.0], target=[5.0, 9.0, 0.0], image_size=(W, H), fov_deg=80)


def test_projection_and_rays_are_inverse(cam):
    X = np.array([[1.0, 2.0, 0.0], [9.0, 18.0, 2.0], [5.0, 10.0, 0.9]])
    px = cam.project(X)
    o, d = cam.rays(px)
    # each 3D point lies on its own line of sight
    v = X - o
    along = np.sum(v * d, axis=1)
    np.testing.assert_allclose(o + along[:, None] * d, X, atol=1e-9)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    np.testing.assert_allclose(cam.project_normalized(X), px / [W, H])


def test_point_behind_camera_is_nan(cam):
    px = cam.project([[5.0, -10.0, 6.0]])
    assert np.isnan(px).all()


def test_decompose_recovers_krt_up_to_scale_and_sign(cam):
    K, R, t = decompose_projection(-3.7 * cam.P)
    np.testing.assert_allclose(K, cam.K, atol=1e-8)
    np.testing.assert_allclose(R, cam.R, atol=1e-10)
    np.testing.assert_allclose(t, cam.t, atol=1e-8)


def test_degenerate_projection_rejected():
    with pytest.raises(ValueError, match="singular"):
        Camera(P=np.zeros((3, 4)), image_size=(W, H))


def test_camera_yaml_round_trip(tmp_path, cam):
    cam.rms_px = 0.5
    cam.residuals_px = {"near_left": 0.25}
    path = cam.save(tmp_path / "camera.yaml")
    back = Camera.load(path)
    np.testing.assert_allclose(back.P, cam.P)
    np.testing.assert_allclose(back.centre, cam.centre)
    assert back.image_size == (W, H) and back.rms_px == 0.5 and back.residuals_px == {"near_left": 0.25}


def test_distorted_camera_rays_invert_projection(tmp_path, cam):
    d = Camera.from_krt(cam.K, cam.R, cam.t, (W, H), dist=[-0.2, 0.05, 0.001, -0.001, 0])
    X = np.array([[0.5, 1.0, 0.0], [9.0, 19.0, 2.5]])
    o, r = d.rays(d.project(X))
    along = np.sum((X - o) * r, axis=1)
    np.testing.assert_allclose(o + along[:, None] * r, X, atol=1e-4)
    np.testing.assert_allclose(Camera.load(d.save(tmp_path / "c.yaml")).dist, d.dist)


@pytest.mark.parametrize(
    "body, match",
    [
        ("image_size: [1280, 720]\n", "needs the keys"),
        ("image_size: [1280, 720]\nP: [[1, 2], [3, 4]]\n", r"\(3, 4\)"),
        ("image_size: [0, 720]\nP: [[1,0,0,0],[0,1,0,0],[0,0,1,0]]\n", "image_size must be positive"),
        ("image_size: [1280, 720]\nP: [[0,0,0,0],[0,0,0,0],[0,0,0,0]]\n", "singular"),
        ("P: {", "not valid YAML"),
    ],
)
def test_bad_camera_yaml(tmp_path, body, match):
    path = tmp_path / "camera.yaml"
    path.write_text(body)
    with pytest.raises(FormatError, match=match) as e:
        Camera.load(path)
    assert "camera.yaml" in str(e.value)


def test_missing_camera_yaml_says_how_to_make_it(tmp_path):
    with pytest.raises(FormatError, match="rally3d calibrate"):
        Camera.load(tmp_path / "camera.yaml")


@pytest.mark.parametrize(
    "X, event, plane",
    [
        ([0.0, 1.0, 2.5], "wall_left", "glass_left"),      # on the 3 m section of the left glass
        ([10.0, 17.0, 1.2], "wall_right", "glass_right_far"),
        ([4.0, 20.0, 1.0], "wall_far", "glass_far"),
        ([6.0, 0.0, 2.0], "wall_near", "glass_near"),        # seen through the near glass
        ([3.0, 14.0, 0.0], "ground", "floor"),
        ([7.0, 10.0, 0.5], "net", "net"),
    ],
)
def test_ray_through_projected_wall_point_hits_that_wall(cam, padel, X, event, plane):
    X = np.array([X])
    o, d = cam.rays(cam.project(X))
    hit = intersect_event(o, d, padel, event)
    assert hit.plane_names() == [plane]
    np.testing.assert_allclose(hit.points, X, atol=1e-6)


def test_ray_outside_extent_misses(cam, padel):
    # the left wall at y = 10 is mesh, not glass: no wall_left contact there, but a mesh contact
    X = np.array([[0.0, 10.0, 1.5]])
    o, d = cam.rays(cam.project(X))
    assert not intersect_event(o, d, padel, "wall_left").valid[0]
    hit = intersect_event(o, d, padel, "mesh")
    assert hit.plane_names() == ["mesh_left"]
    # above the step of the side glass (y = 3, z = 2.5) is open air
    X = np.array([[0.0, 3.0, 2.5]])
    o, d = cam.rays(cam.project(X))
    assert not intersect_event(o, d, padel, "wall_left").valid[0]


def test_grouped_event_resolves_first_valid_plane(cam, padel):
    group = ["ground", "wall_far", "wall_left", "wall_right"]
    X = np.array([[3.0, 15.0, 0.0], [2.0, 20.0, 1.5], [0.0, 18.5, 2.0], [10.0, 2.5, 1.0]])
    o, d = cam.rays(cam.project(X))
    hit = intersect_event(o, d, padel, group)
    assert hit.plane_names() == ["floor", "glass_far", "glass_left_far", "glass_right"]
    np.testing.assert_allclose(hit.points, X, atol=1e-6)


def test_ball_radius_offset(cam, padel):
    r = padel.ball.radius
    X = np.array([[3.0, 14.0, r], [0.0 + r, 1.0, 2.0]])  # ball centres touching floor and left glass
    o, d = cam.rays(cam.project(X))
    np.testing.assert_allclose(intersect_event(o[:1], d[:1], padel, "ground", offset=r).points, X[:1], atol=1e-9)
    np.testing.assert_allclose(intersect_event(o[1:], d[1:], padel, "wall_left", offset=r).points, X[1:], atol=1e-9)


def test_two_sided_net_offset_moves_towards_camera(cam, padel):
    r = padel.ball.radius
    X = np.array([[5.0, 10.0 - r, 0.5]])
    o, d = cam.rays(cam.project(X))
    t, p = intersect_plane(o, d, padel.plane("net"), offset=r)
    np.testing.assert_allclose(p, X, atol=1e-9)


def test_ray_pointing_away_and_parallel_miss(padel):
    floor = padel.plane("floor")
    o = np.array([[5.0, 5.0, 2.0], [5.0, 5.0, 2.0]])
    d = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    t, p = intersect_plane(o, d, floor)
    assert np.isnan(t).all() and np.isnan(p).all()
    assert not intersect_planes(o, d, [floor]).valid.any()
    with pytest.raises(KeyError, match="no plane for event"):
        intersect_event(o, d, padel, "player_near")
