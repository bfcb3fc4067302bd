"""The renderer draws what the geometry says: the ball where the camera projects it, hidden behind a
player, streaked when fast, mirrored in the glass, shadowed on the floor; reproducible."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from inference.camera import Camera
from inference.court import load_court
from synth.bodies import articulate
from synth.render import Appearance, CourtRenderer, ball_exposure, exposure_times
from synth.types import BallPath, InactiveBall, PlayerPlan

SIZE = (1280, 720)
FPS = 30.0


@pytest.fixture(scope="module")
def court():
    return load_court("padel")


@pytest.fixture(scope="module")
def camera():
    # high behind the near wall, so that the lines of sight used below pass above the near glass and mesh
    return Camera.from_look_at([5.0, -2.0, 7.0], [5.0, 9.0, 0.0], SIZE, fov_deg=70)


@pytest.fixture(scope="module")
def plain():
    return replace(Appearance.plain(), light_dir=(0.0, 0.0, -1.0))


@pytest.fixture(scope="module")
def renderer(court, camera, plain):
    return CourtRenderer(court, camera, plain)


def still(p, n=11):
    """(n, 3) exposure samples of a ball at rest at ``p``."""
    return np.tile(np.asarray(p, float), (n, 1))


def moving(p, v, shutter=1.0, n=11):
    """(n, 3) exposure samples of a ball at ``p`` at the frame time moving at ``v`` (m/s)."""
    return np.asarray(p, float) + np.outer(np.linspace(-0.5, 0.5, n) * shutter / FPS, v)


def standing_player(x, y, heading=0.0, n=10):
    t = np.arange(n) / FPS
    plan = PlayerPlan(0, "near", "right", 1.8, t, np.tile([x, y], (n, 1)), np.full(n, heading))
    return articulate(plan, FPS, np.random.default_rng(0))


def pixel(img, xy):
    x, y = np.round(xy).astype(int)
    return img[y, x].astype(int)


def colour_mask(img, colour, tol=40):
    return np.linalg.norm(img.astype(int) - np.asarray(colour), axis=-1) < tol


def test_ball_is_drawn_where_the_camera_projects_it(renderer, camera, plain):
    p = np.array([5.0, 5.0, 1.0])
    img, info = renderer.render(0, still(p), poses=[])
    xy = camera.project(p[None])[0]
    assert info.ball.visibility == 1
    np.testing.assert_allclose([info.ball.x, info.ball.y], xy, atol=1e-9)
    expected_r = camera.K[0, 0] * load_court("padel").ball.radius / camera.depth(p[None])[0]
    assert info.ball.radius_px == pytest.approx(expected_r)
    assert np.abs(pixel(img, xy) - np.array(plain.ball)).max() <= 6
    # ball-coloured pixels form a disc of that radius around the projection
    ys, xs = np.nonzero(colour_mask(img, plain.ball))
    assert np.hypot(xs.mean() - xy[0], ys.mean() - xy[1]) < 0.5
    assert abs(np.sqrt(len(xs) / np.pi) - expected_r) < 1.0
    # nothing else changed away from the ball and its shadow
    bg = renderer.background()
    grid = np.meshgrid(np.arange(SIZE[0]), np.arange(SIZE[1]))
    shadow = camera.project((p * [1, 1, 0])[None])[0]
    far = np.ones(SIZE[::-1], bool)
    for c in (xy, shadow):
        far &= np.hypot(grid[0] - c[0], grid[1] - c[1]) > expected_r + 15
    np.testing.assert_array_equal(img[far], bg[far])


def test_ball_outside_the_image_reports_visibility_0(renderer):
    for p in ([-15.0, 5.0, 1.0], [5.0, -6.0, 1.0]):  # far to the left; behind the camera
        img, info = renderer.render(0, still(p), poses=[])
        assert info.ball.visibility == 0
        np.testing.assert_array_equal(img, renderer.background())


def test_no_ball_in_play(renderer):
    img, info = renderer.render(0, None, poses=[])
    assert info.ball is None
    np.testing.assert_array_equal(img, renderer.background())


def test_ball_hidden_behind_a_player(renderer, camera, plain):
    pose = standing_player(5.0, 6.0)
    chest = np.array([5.0, 6.0, 1.25])
    hidden = camera.centre + 1.1 * (chest - camera.centre)  # on the line of sight, 1 m behind the chest
    img, info = renderer.render(0, still(hidden), poses=[pose])
    assert info.ball.visibility == 3 and info.ball.occluded_by == 0
    xy = camera.project(hidden[None])[0]
    assert np.abs(pixel(img, xy) - np.array(plain.ball)).max() > 60
    assert not colour_mask(img, plain.ball, tol=25).any()
    # the same ball in front of the player is visible and drawn over the body
    front = camera.centre + 0.9 * (chest - camera.centre)
    img, info = renderer.render(0, still(front), poses=[pose])
    assert info.ball.visibility == 1
    assert np.abs(pixel(img, camera.project(front[None])[0]) - np.array(plain.ball)).max() <= 6


def test_player_pixels_and_keypoints(renderer, camera, plain):
    pose = standing_player(5.0, 6.0, heading=np.pi)
    img, info = renderer.render(0, None, poses=[pose])
    (player,) = info.players
    np.testing.assert_allclose(player.keypoints, camera.project(pose.joints[0]))
    assert (player.keypoint_vis == 2).all()
    x0, y0, x1, y1 = player.bbox
    assert (player.keypoints[:, 0] >= x0).all() and (player.keypoints[:, 0] <= x1).all()
    assert (player.keypoints[:, 1] >= y0).all() and (player.keypoints[:, 1] <= y1).all()
    shoulders = pose.joints[0, [5, 6]].mean(0)
    hips = pose.joints[0, [11, 12]].mean(0)
    chest = camera.project((0.6 * shoulders + 0.4 * hips)[None])[0]
    assert np.abs(pixel(img, chest) - np.array(plain.players[0].shirt)).max() < 50
    ys, xs = np.nonzero(np.any(img != renderer.background(), axis=-1))  # the body and its shadow below it
    assert xs.min() >= x0 - 20 and xs.max() <= x1 + 20 and ys.min() >= y0 - 2


def streak_length(img, bg, along=0):
    changed = np.abs(img.astype(int) - bg.astype(int)).sum(-1) > 20
    coords = np.nonzero(changed)[1 - along]
    return coords.max() - coords.min() + 1


def test_fast_ball_is_a_longer_streak(renderer):
    bg = renderer.background()
    p = [5.0, 5.0, 1.2]
    slow_img, slow = renderer.render(0, moving(p, [1.0, 0, 0]), poses=[])
    fast_img, fast = renderer.render(0, moving(p, [30.0, 0, 0]), poses=[])
    slow_len, fast_len = streak_length(slow_img, bg), streak_length(fast_img, bg)
    assert fast_len > slow_len + 30
    assert fast.ball.streak_px > 8 * fast.ball.radius_px and fast.ball.visibility == 2  # hard to see
    assert slow.ball.visibility == 1
    # blur spreads the same ball over more pixels: the streak is fainter than the still ball
    still_img, _ = renderer.render(0, still(p), poses=[])
    assert np.abs(fast_img.astype(int) - bg).sum(-1).max() < np.abs(still_img.astype(int) - bg).sum(-1).max()


def test_reflection_in_the_glass(court, camera, plain, renderer):
    near_glass = np.array([0.4, 18.0, 1.0])  # 40 cm from the far part of the left side glass
    mirrored = near_glass * [-1, 1, 1]
    xy = camera.project(mirrored[None])[0]
    bg = renderer.background()
    img, info = renderer.render(0, still(near_glass), poses=[])
    assert "glass_left_far" in [m.key for m in info.reflections]
    info.reflections = [m for m in info.reflections if m.key == "glass_left_far"]
    np.testing.assert_allclose([info.reflections[0].x, info.reflections[0].y], xy)
    assert np.abs(pixel(img, xy) - pixel(bg, xy)).sum() > 30
    assert np.hypot(*(xy - camera.project(near_glass[None])[0])) > 20  # not the ball itself
    off = CourtRenderer(court, camera, replace(plain, reflection_strength=0.0))
    img_off, info_off = off.render(0, still(near_glass), poses=[])
    assert info_off.reflections == []
    np.testing.assert_array_equal(pixel(img_off, xy), pixel(bg, xy))
    # mid-court the ball is too far from any glass to be mirrored
    _, info_mid = renderer.render(0, still([5.0, 10.0, 1.0]), poses=[])
    assert info_mid.reflections == []


def test_reflection_requires_the_line_of_sight_through_the_glass(renderer):
    # near the far glass but high: the mirrored point is seen through the mesh above the glass, not the glass
    _, info = renderer.render(0, still([5.0, 19.6, 3.6]), poses=[])
    assert "glass_far" not in [m.key for m in info.reflections]
    _, info = renderer.render(0, still([5.0, 19.6, 1.0]), poses=[])
    assert "glass_far" in [m.key for m in info.reflections]


def test_shadow_on_the_floor_under_the_ball(renderer, camera):
    ball = np.array([5.0, 6.0, 0.6])
    floor = camera.project((ball * [1, 1, 0])[None])[0]
    img, _ = renderer.render(0, still(ball), poses=[])
    bg = renderer.background()
    assert (pixel(img, floor) < pixel(bg, floor) - 15).all()  # darker, same hue
    beside = camera.project(np.array([[5.4, 6.0, 0.0]]))[0]
    np.testing.assert_array_equal(pixel(img, beside), pixel(bg, beside))
    assert np.hypot(*(floor - camera.project(ball[None])[0])) > 10  # the ball itself is elsewhere


def test_stationary_balls_are_drawn_with_their_shadow(renderer, camera, plain, court):
    balls = [InactiveBall(0, np.array([2.0, 7.0, court.ball.radius]), 0, 5),
             InactiveBall(1, np.array([8.0, 4.0, court.ball.radius]), 3, 9)]
    img, info = renderer.render(1, None, poses=[], inactive_balls=balls)
    assert [b.key for b in info.inactive_balls] == [0]
    xy = camera.project(balls[0].position[None])[0]
    assert np.abs(pixel(img, xy) - np.array(plain.ball)).max() <= 10
    assert not colour_mask(img[..., :], plain.ball)[int(camera.project(balls[1].position[None])[0][1]),
                                                         int(camera.project(balls[1].position[None])[0][0])]


def test_same_seed_gives_identical_bytes(court, camera):
    app = Appearance.sample(np.random.default_rng(3))
    assert app.noise_sigma > 0
    pose = standing_player(4.0, 6.0)
    samples = moving([5.0, 8.0, 1.0], [3.0, 15.0, 2.0], app.shutter)
    a = CourtRenderer(court, camera, app, seed=11).render(4, samples, [pose])[0]
    b = CourtRenderer(court, camera, app, seed=11).render(4, samples, [pose])[0]
    c = CourtRenderer(court, camera, app, seed=12).render(4, samples, [pose])[0]
    assert a.tobytes() == b.tobytes()
    assert a.tobytes() != c.tobytes()


def test_sampled_appearances_render(court, camera):
    for seed, sport in ((0, "padel"), (1, "tennis")):
        app = Appearance.sample(np.random.default_rng(seed), sport)
        tennis_cam = Camera.from_look_at([5.5, -6, 7], [5.5, 12, 0], SIZE, fov_deg=70)
        cam = camera if sport == "padel" else tennis_cam
        r = CourtRenderer(load_court(sport), cam, app)
        ball = moving([4.0, 8.0, 1.0], [2.0, 20.0, 1.0], app.shutter)
        img, info = r.render(0, ball, [standing_player(4, 3)])
        assert img.shape == (SIZE[1], SIZE[0], 3) and img.dtype == np.uint8
        assert info.ball.visibility in (1, 2)


def test_painted_lines_are_where_the_camera_projects_them(renderer, camera, court, plain):
    bg = renderer.background()
    checked = 0
    for a, b in court.lines["paint"]:
        xy = camera.project((0.7 * a + 0.3 * b)[None])[0]  # 0.3 along: away from the net
        if not (0 <= xy[0] < SIZE[0] - 1 and 0 <= xy[1] < SIZE[1] - 1):
            continue
        x, y = np.round(xy).astype(int)
        brightest = bg[y - 1:y + 2, x - 1:x + 2].astype(int).sum(-1).max()  # far lines are thin: ±1 px
        assert brightest > sum(plain.floor) + 0.3 * (sum(plain.line) - sum(plain.floor))
        checked += 1
    assert checked >= 5


def test_exposure_helpers():
    t = exposure_times(3, FPS, 0.5, n=5)
    np.testing.assert_allclose(t, 3 / FPS + np.linspace(-0.25, 0.25, 5) / FPS)
    times = np.arange(0, 1, 0.001)
    pos = np.c_[times * 10, np.zeros_like(times), np.ones_like(times)]
    path = BallPath(times, pos, np.zeros_like(pos), np.zeros_like(pos), np.ones_like(times, bool))
    s = ball_exposure(path, 3, FPS, 0.5, n=5)
    np.testing.assert_allclose(s[:, 0], 10 * t)
    assert ball_exposure(path, 60, FPS, 0.5) is None


@pytest.fixture(scope="module")
def tv_camera():
    # a tour event's main camera: high, far behind the near glass, a longer lens
    return Camera.from_look_at([5.0, -13.5, 7.5], [5.0, 8.0, 0.0], SIZE, fov_deg=52)


def test_tour_look_changes_only_its_own_fields():
    base = Appearance.sample(np.random.default_rng(5))
    assert base.perimeter_paint and base.glass_base is None and not base.posts and not base.floor_logos
    assert base.scoreboard is None and base.near_board is None
    tour = base.tour(np.random.default_rng(1))
    changed = {f for f in vars(base) if getattr(tour, f) != getattr(base, f)}
    assert changed <= {"frame", "mesh", "mesh_alpha", "glass_joints", "perimeter_paint", "glass_base",
                       "glass_base_width", "posts", "floor_logos", "logo", "logo_alpha", "scoreboard",
                       "near_board", "board", "tour_seed"}
    assert not tour.perimeter_paint and tour.glass_base is not None and tour.posts and tour.floor_logos
    assert tour.scoreboard is not None and tour.near_board is not None


def test_tour_outline_is_the_glass_base_not_paint(court, tv_camera, plain):
    """The court's outline is not painted; the glass stands on a bright base profile just outside the court,
    only where there is glass (4 m from each back wall along the sides), and posts stand along the mesh."""
    red = (250, 30, 30)
    club = CourtRenderer(court, tv_camera, plain)
    tour = CourtRenderer(court, tv_camera, replace(plain, perimeter_paint=False, glass_base=red,
                                                   glass_base_width=0.2, posts=True))
    a, b = club.background(), tour.background()
    px = lambda p: tv_camera.project(np.array([p], float))[0]  # noqa: E731
    side_mid = px([0.0, 7.0, 0.0])  # the left side line along the mesh: painted in the club look only
    assert pixel(a, side_mid).sum() > pixel(b, side_mid).sum() + 150
    service = px([2.5, 3.05, 0.0])  # painted lines inside the court stay
    assert np.abs(pixel(a, service) - pixel(b, service)).max() <= 3
    redness = lambda p: int(pixel(b, px(p))[0]) - int(pixel(b, px(p))[1])  # noqa: E731  (through the glass)
    assert redness([-0.1, 1.0, 0.0]) > 80 and redness([10.1, 19.0, 0.0]) > 80  # under the side glass
    assert redness([-0.1, 7.0, 0.0]) < 20  # beside the mesh: no glass, no base
    assert len(tour.overlays) > len(club.overlays)  # the posts


def test_tour_board_hides_the_near_baseline_and_the_score_box_stays_put(court, tv_camera, plain):
    look = replace(plain, near_board=(-1.5, 1.3), scoreboard=(0.03, 0.05, 0.23, 0.15), tour_seed=4)
    r = CourtRenderer(court, tv_camera, look)
    img0, info = r.render(0, still([5.0, 0.3, 0.1]), [])
    img1, _ = r.render(5, None, [standing_player(4, 3)])
    assert info.ball.visibility == 3  # behind the board
    x, y = np.round(tv_camera.project(np.array([[5.0, 0.0, 0.0]]))[0]).astype(int)  # the near baseline
    assert colour_mask(img0, look.board, tol=30)[y, x]
    rows = slice(int(0.05 * SIZE[1]), int(0.15 * SIZE[1]))
    cols = slice(int(0.03 * SIZE[0]), int(0.23 * SIZE[0]))
    box = img0[rows, cols]
    assert box.tobytes() == img1[rows, cols].tobytes()
    assert box.mean() < 120  # a dark panel with light text
