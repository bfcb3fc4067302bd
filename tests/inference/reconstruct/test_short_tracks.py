"""Short tracks with real ball physics (hit → bounce → a few frames, 25 fps, σ 2–3 px), simulated outside
the rally generator: every track is reconstructed, with the hit and the bounce as events, with the
bounce alone and with the hitter's court position (players.csv), and the error is small across the line of
sight and bounded along it (the depth does not slide by metres) — on a tennis court and, at the scale of the
motion-capture tracks of the literature, on a table-tennis table."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from inference.camera import Camera
from inference.clipio import PlayerTracks
from inference.court import load_court
from inference.physics import FlightModel, bounce, integrate
from inference.reconstruct import Observations
from inference.reconstruct.joint import JointConfig, fit_joint
from inference.reconstruct.observations import contact_priors
from synth.short_tracks import FPS, VIEWS, draw_tracks, hitter_players

SIZE = (1280, 720)


@pytest.fixture(scope="module")
def tracks():
    court = load_court("tennis")
    return court, draw_tracks(court, 6, 5)


@pytest.mark.parametrize("events", ["hit + bounce", "bounce only", "hit + bounce + hitter"])
def test_every_short_track_is_reconstructed_from_behind(tracks, events):
    court, trs = tracks
    eye, target, fov = VIEWS["tennis"]["behind"]
    cam = Camera.from_look_at(eye, target, SIZE, fov_deg=fov)
    along, across = [], []
    for k, tr in enumerate(trs):
        rng = np.random.default_rng(k)
        uv = cam.project(tr["xyz"]) + rng.normal(0.0, rng.uniform(2.0, 3.0), (len(tr["xyz"]), 2))
        uv[~((uv >= 0) & (uv < SIZE)).all(axis=1)] = np.nan                     # outside the image
        ev, lab = ([tr["hit"], tr["bounce"]], ["player_near", "ground"]) if events.startswith("hit") else \
            ([tr["bounce"]], ["ground"])
        players = hitter_players(np.random.default_rng(100 + k), tr) if "hitter" in events else None
        obs = Observations(court, cam, FPS, uv, np.array(ev), lab, players)
        b = fit_joint(obs, JointConfig(pixel_sigma=2.5)).ball_3d()
        seen = np.flatnonzero(np.isfinite(uv).all(axis=1))
        assert np.isin(seen, b.frame).all(), (k, events)                         # the whole track
        gt = tr["xyz"][b.frame]
        ray = gt - cam.centre
        ray /= np.linalg.norm(ray, axis=1)[:, None]
        d = b.xyz - gt
        a = np.einsum("ij,ij->i", d, ray)
        along.append(np.abs(a))
        across.append(np.linalg.norm(d - a[:, None] * ray, axis=1))
    # 30 tracks (bench/bench_short_tracks.py): along 0.106 / 0.112 m, across 0.015 m; here per track 0.04–0.62
    assert np.median(np.concatenate(along)) < 0.5 and np.median(np.concatenate(across)) < 0.03


TT_VIEWS = {k: v for k, v in VIEWS["table_tennis"].items() if not k.startswith("facing")}


def _tt_tracks(seed: int, n: int):
    court = load_court("table_tennis")
    return court, draw_tracks(court, n, seed)


def _fit_errors(court, cam, tr, k: int, bounce_only: bool):
    """(seen frames, fitted frames, along-ray and across-ray errors (M,)) of one noisy track."""
    rng = np.random.default_rng(k)
    uv = cam.project(tr["xyz"]) + rng.normal(0.0, rng.uniform(2.0, 3.0), (len(tr["xyz"]), 2))
    uv[~((uv >= 0) & (uv < SIZE)).all(axis=1)] = np.nan
    ev, lab = ([tr["bounce"]], ["ground"]) if bounce_only else ([tr["hit"], tr["bounce"]], ["player_near", "ground"])
    b = fit_joint(Observations(court, cam, FPS, uv, np.array(ev), lab), JointConfig(pixel_sigma=2.5)).ball_3d()
    gt = tr["xyz"][b.frame]
    ray = gt - cam.centre
    ray /= np.linalg.norm(ray, axis=1)[:, None]
    d = b.xyz - gt
    a = np.einsum("ij,ij->i", d, ray)
    return np.flatnonzero(np.isfinite(uv).all(axis=1)), b.frame, np.abs(a), np.linalg.norm(d - a[:, None] * ray, axis=1)


@pytest.mark.parametrize("view", sorted(TT_VIEWS))
def test_table_tennis_tracks_are_reconstructed_within_centimetres(view):
    court, trs = _tt_tracks(5, 6)
    eye, target, fov = TT_VIEWS[view]
    cam = Camera.from_look_at(eye, target, SIZE, fov_deg=fov)
    for bounce_only in (False, True):
        along, across = [], []
        for k, tr in enumerate(trs):
            seen, fitted, a, c = _fit_errors(court, cam, tr, k, bounce_only)
            assert np.isin(seen, fitted).all(), (view, k, bounce_only)          # every track, every frame
            along.append(a)
            across.append(c)
        A, C = np.concatenate(along), np.concatenate(across)
        # 30 tracks (bench_short_tracks.py --sport table_tennis): along-ray median 0.04-0.05 m, across < 1 cm
        assert np.median(A) < 0.10 and np.median(C) < 0.02 and A.max() < 0.6, (view, bounce_only, A.max())


def test_a_run_out_restarts_from_its_bounce_rebound():
    """Without the impact model (the solver's first pass) a run-out's depth rests on its 2D track alone and can
    fit going the wrong way along the line of sight; the impact model's rebound of the incoming flight restarts
    it (Problem.seed_runouts). Track 16 of bench_short_tracks.py's draw (tennis, oblique view, the bounce as the
    only event) had its run-out 34 m off before; the other tracks' worst frame is 1.6 m."""
    court = load_court("tennis")
    trs = draw_tracks(court, 17, 0)
    eye, target, fov = VIEWS["tennis"]["oblique"]
    cam = Camera.from_look_at(eye, target, SIZE, fov_deg=fov)
    tr, r2 = trs[16], np.random.default_rng(16)
    uv = cam.project(tr["xyz"]) + r2.normal(0.0, r2.uniform(2.0, 3.0), (len(tr["xyz"]), 2))
    uv[~((uv >= 0) & (uv < SIZE)).all(axis=1)] = np.nan
    b = fit_joint(Observations(court, cam, FPS, uv, np.array([tr["bounce"]]), ["ground"]),
                  JointConfig(pixel_sigma=2.5)).ball_3d()
    run_out = b.frame > tr["bounce"]
    assert run_out.sum() >= 3
    err = np.linalg.norm(b.xyz - tr["xyz"][b.frame], axis=1)
    assert err[run_out].max() < 1.0, err[run_out]
    assert np.all(np.diff(b.xyz[run_out, 1]) > 0)                   # still going away, towards the far baseline


def _mean_error(court, view, tr, rng: np.random.Generator, bounce_only: bool, cfg: JointConfig) -> float:
    """Mean 3D error (m) over the fitted frames of one noisy track seen from ``view`` (no players.csv)."""
    cam = Camera.from_look_at(*view[:2], SIZE, fov_deg=view[2])
    uv = cam.project(tr["xyz"]) + rng.normal(0.0, rng.uniform(2.0, 3.0), (len(tr["xyz"]), 2))
    uv[~((uv >= 0) & (uv < SIZE)).all(axis=1)] = np.nan
    ev, lab = ([tr["bounce"]], ["ground"]) if bounce_only else ([tr["hit"], tr["bounce"]], ["player_near", "ground"])
    b = fit_joint(Observations(court, cam, FPS, uv, np.array(ev), lab), cfg).ball_3d()
    return float(np.linalg.norm(b.xyz - tr["xyz"][b.frame], axis=1).mean()) if len(b) else np.inf


@pytest.mark.parametrize("sport, view, picks, bounce_only", [
    ("tennis", "facing 22 m", (11, 15, 49), False),      # the far player's shots at a broadcast camera
    ("table_tennis", "facing 6 m", (8, 10, 46), True),   # a table-tennis shot at a camera behind the far end
])
def test_a_shot_flying_at_the_camera_keeps_its_depth_without_players(sport, view, picks, bounce_only):
    """Seen from behind the play, a ball flying at the camera and one flying away draw nearly the same 2D
    track; with no hitter position (no players.csv) the first guess put the racket hit (or the lead-in's
    motion) on the wrong side of that ambiguity and the fit stayed there, 2–4 m off with a higher cost than
    near the truth (bench_short_tracks.py: tennis 14 of 60 tracks over 1 m, table tennis 8 of 60). The fit is
    now started again from other depths along the line of sight (``JointConfig.depth_restarts``). These are
    tracks of bench_short_tracks.py's draw (seed 1) that were 2–4 m off; with the restarts off they still are."""
    court = load_court(sport)
    trs = draw_tracks(court, max(picks) + 1, 1)
    view_ = VIEWS[sport][view]
    for k in picks:
        now = _mean_error(court, view_, trs[k], np.random.default_rng(1000 + k), bounce_only,
                          JointConfig(pixel_sigma=2.5))
        assert now < 1.0, (k, now)
    off = _mean_error(court, view_, trs[picks[0]], np.random.default_rng(1000 + picks[0]), bounce_only,
                      JointConfig(pixel_sigma=2.5, depth_restarts=0))
    assert off > 1.5, off                                 # the case the test is about: still there without them


DT = 1.0 / 1000.0      # s, the integration step of the hand-made tracks below


def _floor_bounce(court, flight, seconds: float):
    """The sample index where ``flight`` (FlightSamples) first reaches the floor, and the flight after its
    rebound (the court's floor material) integrated for ``seconds``."""
    r = court.ball.radius
    k = int(np.flatnonzero(flight.pos[:, 0, 2] <= r)[0])
    mat = court.materials[court.planes_for("ground")[0].material]
    v_out, w_out = bounce(flight.vel[k], flight.spin[k], np.array([0.0, 0.0, 1.0]), mat.restitution, mat.friction, r)
    after = integrate(flight.pos[k, 0] * [1, 1, 0] + [0, 0, r], v_out[0], w_out[0], seconds,
                      FlightModel.from_ball(court.ball), DT)
    return k, after


def _stitch(pieces: list, n: int, fps: float) -> np.ndarray:
    """(n, 3) positions at frames 0 … n−1 of consecutive flights ``[(FlightSamples, seconds it lasts), …]``
    (the last one lasts to the end)."""
    pos = np.empty((n, 3))
    for i in range(n):
        t = i / fps
        for k, (flight, length) in enumerate(pieces):
            if k == len(pieces) - 1 or t <= length:
                pos[i] = flight.pos[int(round(t / DT)), 0]
                break
            t -= length
    return pos


def _far_serve(court, fps: float = FPS) -> tuple[np.ndarray, int, int]:
    """A serve from the far baseline: a 12-frame toss (up 4.5 m/s from 1.9 m), the hit at 2.9 m, the ball into
    the near service box and 6 frames after its bounce. Returns (xyz (n, 3), hit frame, bounce frame)."""
    model = FlightModel.from_ball(court.ball)
    hit_frame = 12
    toss = integrate(np.array([4.9, 23.9, 1.9]), np.array([0.0, -0.2, 4.5]), np.zeros(3), hit_frame / fps, model, DT)
    serve = integrate(toss.pos[-1, 0], np.array([-1.5, -38.0, -4.0]), np.array([-250.0, 0.0, 0.0]), 1.5, model, DT)
    k, after = _floor_bounce(court, serve, 0.5)
    pos = _stitch([(toss, toss.t[-1]), (serve, serve.t[k]), (after, None)], hit_frame + int(serve.t[k] * fps) + 7, fps)
    return pos, hit_frame, hit_frame + int(round(serve.t[k] * fps))


@pytest.mark.parametrize("lead_in_back_sigma", [2.0, 0.0])
def test_a_serve_toss_is_not_fitted_as_a_ball_from_beyond_the_baseline(lead_in_back_sigma):
    """The lead-in before a far serve (the toss: slow, nearly vertical, seen from behind the other baseline)
    fits about as well as a ball flying at the camera from metres behind the server; with nothing behind the
    server to rebound from, a lead-in reaching the hit towards the net is a hinge (Problem._lead_in_from_behind).
    Over 8 noise draws the toss stays within 2 m (its worst frame; 1.5 m: a toss drifting towards the server,
    which the hinge allows); without the hinge two draws put it 7.8 m off."""
    court = load_court("tennis")
    xyz, hit, bnc = _far_serve(court)
    cam = Camera.from_look_at((5.5, -16.0, 6.0), (5.5, 14.0, 0.0), SIZE, fov_deg=50.0)
    worst = []
    for k in range(8):
        rng = np.random.default_rng(k)
        uv = cam.project(xyz) + rng.normal(0.0, 2.0, (len(xyz), 2))
        server = PlayerTracks(np.array([hit]), np.array([1]), ["far"], np.array([1.0]), np.full((1, 4), np.nan),
                              np.full((1, 17, 3), np.nan), np.array([[5.1, 24.2]]))      # behind the ball
        obs = Observations(court, cam, FPS, uv, np.array([hit, bnc]), ["player_far", "ground"], server)
        b = fit_joint(obs, JointConfig(lead_in_back_sigma=lead_in_back_sigma)).ball_3d()
        toss = b.frame < hit
        assert toss.sum() >= 10
        worst.append(np.linalg.norm(b.xyz[toss] - xyz[b.frame[toss]], axis=1).max())
    if lead_in_back_sigma:
        assert max(worst) < 2.0, worst
    else:
        assert max(worst) > 3.0, worst          # the test bites: the failure it guards against is there


def _server_pose(cam, frame: int, feet_xy, wrist_z: float) -> PlayerTracks:
    """players.csv of a far server at ``feet_xy`` whose racket (right) wrist is at ``wrist_z`` m: COCO-17
    keypoints projected from a standing body (shoulders 1.5 m, the other wrist at the hip)."""
    x, y = feet_xy
    joints = np.full((17, 3), np.nan)
    joints[5], joints[6] = (x - 0.2, y, 1.5), (x + 0.2, y, 1.5)          # shoulders
    joints[9], joints[10] = (x - 0.25, y, 0.95), (x + 0.3, y - 0.1, wrist_z)   # wrists
    joints[11], joints[12] = (x - 0.15, y, 0.95), (x + 0.15, y, 0.95)    # hips
    joints[0] = (x, y, 1.75)                                              # nose
    ok = np.isfinite(joints).all(axis=1)
    kp = np.full((17, 3), np.nan)
    kp[ok, :2] = cam.project(joints[ok]) / np.asarray(SIZE, float)
    kp[ok, 2] = 0.9
    return PlayerTracks(np.array([frame]), np.array([1]), ["far"], np.array([1.0]), np.full((1, 4), np.nan),
                        kp[None], np.array([feet_xy], float))


def test_a_raised_racket_hand_puts_the_hit_above_it():
    """A serve's hand is above the shoulders and the ball above the hand by about the racket (court YAML
    ``hit_prior.raised_above_hand``) and in front of the body (``raised_forward``); a groundstroke's hand is at
    the ball's height. The contact prior reads the hand's height and whether it is raised from the pose; the
    fitted serve contact is nearer the truth for it."""
    court = load_court("tennis")
    xyz, hit, bnc = _far_serve(court)
    cam = Camera.from_look_at((5.5, -16.0, 6.0), (5.5, 14.0, 0.0), SIZE, fov_deg=50.0)
    uv = cam.project(xyz) + np.random.default_rng(0).normal(0.0, 2.0, (len(xyz), 2))
    for wrist_z, raised in ((2.35, True), (1.0, False)):
        obs = Observations(court, cam, FPS, uv, np.array([hit, bnc]), ["player_far", "ground"],
                           _server_pose(cam, hit, (5.1, 24.2), wrist_z))
        prior = contact_priors(obs)[0]
        assert prior.hand_raised is raised and prior.hand_z == pytest.approx(wrist_z, abs=0.05)
    err = {True: np.zeros(3), False: np.zeros(3)}
    for k in range(4):                          # 4 noise draws, the racket hiding the ball around the hit
        uv = cam.project(xyz) + np.random.default_rng(k).normal(0.0, 2.0, (len(xyz), 2))
        uv[hit - 1:hit + 2] = np.nan
        for raised in (True, False):           # the court YAML's raised-hand prior, or the groundstroke's
            hp = {**court.extra["hit_prior"]}
            if not raised:
                hp.pop("raised_forward")
                hp["raised_above_hand"] = 0.0
            obs = Observations(replace(court, extra={**court.extra, "hit_prior": hp}), cam, FPS, uv,
                               np.array([hit, bnc]), ["player_far", "ground"],
                               _server_pose(cam, hit, (5.1, 24.2), 2.35))
            b = fit_joint(obs, JointConfig()).ball_3d()
            err[raised] += np.abs(b.xyz[b.frame == hit][0] - xyz[hit]) / 4
    # the serve is met 0.4 m in front of the server's feet and 0.55 m above the wrist: along the court and in
    # height the raised-hand prior lands nearer on average (0.15 / 0.03 m against 0.19 / 0.04; the track pins
    # the rest)
    assert err[True][1] < err[False][1] and err[True][2] < err[False][2], err


def _net_drop(court, fps: float = FPS) -> tuple[np.ndarray, list[int], list[str]]:
    """A near hit into the net: the ball meets the net at 0.45 m (frame 18), drops back (1.5 m/s towards the
    hitter), bounces on the near side and dribbles for 11 frames. Returns (xyz (n, 3), event frames, labels)."""
    from scipy.optimize import least_squares

    model, r = FlightModel.from_ball(court.ball), court.ball.radius
    p0, target, T = np.array([4.85, -0.6, 1.3]), np.array([5.6, court.net_y - r, 0.45]), 18.4 / fps
    v0 = least_squares(lambda v: integrate(p0, v, np.zeros(3), T, model, DT).pos[-1, 0] - target,
                       np.array([0.5, 17.0, 2.0])).x
    to_net = integrate(p0, v0, np.zeros(3), T, model, DT)
    drop = integrate(target, np.array([0.4, -1.5, -1.0]), np.zeros(3), 1.0, model, DT)
    k, dribble = _floor_bounce(court, drop, 1.0)
    t_b = drop.t[k]
    pos = _stitch([(to_net, T), (drop, t_b), (dribble, None)], int((T + t_b) * fps) + 12, fps)
    return pos, [0, int(round(T * fps)), int(round((T + t_b) * fps))], ["player_near", "net", "ground"]


def test_a_ball_dropping_off_the_net_keeps_its_bounce_and_dribble():
    """Near hit → net → the ball drops back and dribbles, filmed from behind the near baseline (a broadcast
    view). The solver's first pass (no impact model) could drag the bounce 2.5 frames early, through the net,
    with the run-out flying at the camera at 67 m/s (16 m off in 2 of 8 noise draws); the run-out restart
    also takes the bounce and its incoming flight back to where the first pass began them
    (Problem.seed_runouts with θ₀). Every draw now stays within 2 m (worst 1.1 m) and below 3 m; 6 of the 8
    reconstruct every frame (2 report the dribble failed, as before the restart)."""
    court = load_court("tennis")
    xyz, ev, lab = _net_drop(court)
    cam = Camera.from_look_at((6.0, -14.5, 8.5), (5.5, 14.0, 0.0), (1920, 1080), fov_deg=42.7)
    whole = 0
    for k in range(8):
        uv = cam.project(xyz) + np.random.default_rng(k).normal(0.0, 2.0, (len(xyz), 2))
        b = fit_joint(Observations(court, cam, FPS, uv, np.array(ev), lab), JointConfig()).ball_3d()
        whole += bool(np.isin(np.arange(len(xyz)), b.frame).all())
        err = np.linalg.norm(b.xyz - xyz[b.frame], axis=1)
        assert err.max() < 2.0 and b.xyz[:, 2].max() < 3.0, (k, err.max(), b.xyz[:, 2].max())
    assert whole >= 5, whole                 # 6 here; a margin for other CPUs' rounding
