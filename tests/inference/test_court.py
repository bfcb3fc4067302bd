"""Court YAMLs: regulation dimensions, planes and their extents, loader errors."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio.errors import FormatError
from inference.court import load_court, points_in_polygon


@pytest.fixture(scope="module")
def padel():
    return load_court("padel")


@pytest.fixture(scope="module")
def tennis():
    return load_court("tennis")


def dist(court, a, b):
    return float(np.linalg.norm(court.points[a] - court.points[b]))


def test_padel_regulation_dimensions(padel):
    assert dist(padel, "near_left", "near_right") == pytest.approx(10.0)
    assert dist(padel, "near_left", "far_left") == pytest.approx(20.0)
    assert padel.net_y == 10.0
    # service lines 6.95 m from the net
    assert padel.net_y - padel.points["near_service_center"][1] == pytest.approx(6.95)
    assert padel.points["far_service_center"][1] - padel.net_y == pytest.approx(6.95)
    # net 0.88 m at the centre, 0.92 m at the posts
    assert padel.points["net_center_top"][2] == pytest.approx(0.88)
    assert padel.points["net_post_left_top"][2] == pytest.approx(0.92)
    # back glass 3 m, mesh to 4 m; side glass steps 3 m for 2 m, then 2 m for 2 m
    assert padel.points["glass_near_left_top"][2] == pytest.approx(3.0)
    assert padel.points["mesh_far_right_top"][2] == pytest.approx(4.0)
    assert padel.points["step_near_left_high"].tolist() == [0.0, 2.0, 3.0]
    assert padel.points["step_far_right_end"].tolist() == [10.0, 16.0, 2.0]
    r = padel.ball.radius * 2
    assert 0.0635 <= r <= 0.0677
    assert 0.056 <= padel.ball.mass <= 0.0594


def test_tennis_regulation_dimensions(tennis):
    assert dist(tennis, "near_left", "near_right") == pytest.approx(10.97)
    assert dist(tennis, "near_singles_left", "near_singles_right") == pytest.approx(8.23)
    assert dist(tennis, "near_left", "far_left") == pytest.approx(23.77)
    assert tennis.net_y == pytest.approx(11.885)
    assert tennis.net_y - tennis.points["near_service_center"][1] == pytest.approx(6.40)
    assert tennis.points["net_center_top"][2] == pytest.approx(0.914)
    assert tennis.points["net_post_left_top"][2] == pytest.approx(1.07)
    # posts 0.914 m outside the doubles side lines
    assert -tennis.points["net_post_left"][0] == pytest.approx(0.914)
    assert tennis.points["net_post_right"][0] - 10.97 == pytest.approx(0.914)
    assert 0.0654 <= 2 * tennis.ball.radius <= 0.0686


@pytest.mark.parametrize("name", ["padel", "tennis"])
def test_court_has_off_ground_points_and_ground_corners(name):
    court = load_court(name)
    for p in ("near_left", "near_right", "far_left", "far_right", "net_post_left_top"):
        assert p in court.points
    assert len(court.off_ground_points()) >= 3
    assert court.planes_for("ground")[0].normal.tolist() == [0.0, 0.0, 1.0]


def test_padel_plane_normals_point_into_court(padel):
    centre = np.array([5.0, 10.0, 1.0])
    for plane in padel.planes:
        if plane.two_sided:
            continue
        assert (centre - plane.origin) @ plane.normal > 0, plane.name


def test_padel_side_glass_extent(padel):
    left = padel.planes_for("wall_left")
    # (y, z) on the left wall: glass at y=1,z=2.5 and y=3,z=1.5; not at y=3,z=2.5 (above the step) nor y=10
    def on_glass(y, z):
        p = np.array([[0.0, y, z]])
        return any(pl.contains(p)[0] for pl in left)

    assert on_glass(1.0, 2.5) and on_glass(3.0, 1.5) and on_glass(19.0, 2.9) and on_glass(17.0, 1.0)
    assert not on_glass(3.0, 2.5) and not on_glass(10.0, 1.0) and not on_glass(17.0, 2.5)
    assert [p.name for p in padel.planes_for("mesh")] == [
        "mesh_near", "mesh_far", "mesh_left", "mesh_right"]


def test_points_in_polygon_edges_and_concave():
    poly = np.array([[0, 0], [4, 0], [4, 2], [2, 2], [2, 3], [0, 3]], dtype=float)
    pts = np.array([[1, 1], [3, 2.5], [4, 1], [0, 0], [2, 2.5], [5, 0]])
    assert points_in_polygon(pts, poly).tolist() == [True, False, True, True, True, False]


def test_unknown_court_lists_known(tmp_path):
    with pytest.raises(FileNotFoundError, match="known courts.*padel"):
        load_court("squash")


@pytest.mark.parametrize(
    "body, match",
    [
        ("name: x\n", "missing keys"),
        ("[1, 2]\n", "mapping"),
        ("name: x\npoints: {a: [1, 2]}\nplanes: []\nmaterials: {}\nball: {radius: 0.03, mass: 0.05, "
         "drag_coefficient: 0.5}\n", r"points\.a must be a list of 3 numbers"),
        ("name: x\npoints: {}\nplanes: [{name: f, event: ground, material: rock, origin: [0,0,0], "
         "u: [1,0,0], v: [0,1,0], polygon: [[0,0],[1,0],[1,1]]}]\nmaterials: {}\n"
         "ball: {radius: 0.03, mass: 0.05, drag_coefficient: 0.5}\n", "undefined materials"),
        ("name: x\npoints: {}\nplanes: [{name: f, event: ground, material: m, origin: [0,0,0], "
         "u: [1,0,0], v: [1,0,0], polygon: [[0,0],[1,0],[1,1]]}]\nmaterials: {m: {restitution: 0.5, "
         "friction: 0.1}}\nball: {radius: 0.03, mass: 0.05, drag_coefficient: 0.5}\n", "orthogonal"),
    ],
)
def test_bad_court_yaml(tmp_path, body, match):
    path = tmp_path / "bad.yaml"
    path.write_text(body)
    with pytest.raises(FormatError, match=match) as e:
        load_court(path)
    assert "bad.yaml" in str(e.value)


def test_new_court_is_just_a_yaml(tmp_path, padel):
    # a court variant (e.g. a padel court with no side mesh planes) needs no code
    text = (padel.source.read_text()).replace("name: padel", "name: padel_variant")
    path = tmp_path / "padel_variant.yaml"
    path.write_text(text)
    court = load_court(path)
    assert court.name == "padel_variant" and court.sport == "padel"


def test_hit_limits_and_event_groups(padel, tennis):
    assert padel.hits.height == (0.0, 2.8) and padel.hits.reach > 0
    assert tennis.hits.height[1] > 2.8  # overhead serves
    group = {p.name for p in padel.planes_for("ground_or_other_wall")}
    assert {"floor", "glass_far", "glass_left", "glass_right_far"} <= group
    assert "glass_near" not in group
