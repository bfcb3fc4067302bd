"""Players pipeline: court positions, tracking through the importer path, selection, teams, bad inputs."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from inference.camera import Camera
from inference.cli import main
from inference.clipio import Clip
from inference.court import load_court
from inference.players import Persons, PoseSequence
from inference.players.backends import BackendUnavailable, decode_movenet, make_backend
from inference.players.evaluate import DetectionNoise, score, simulate_detections
from inference.players.positions import court_positions, foot_points
from inference.players.tracking import players_from_poses
from inference.players.skeleton import JOINT

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample"
W, H = 1280, 720


@pytest.fixture(scope="module")
def cam():
    return Camera.from_look_at([5.0, -3.0, 6.0], [5.0, 9.5, 0.0], (W, H), fov_deg=80)


def person_at(cam, x, y, height=1.8):
    """(17, 2) keypoints of an upright person standing at (x, y): ankles at 0.08 m, knees, hips, head."""
    z = {"ankle": 0.08, "knee": 0.5, "hip": 0.95, "shoulder": 1.45, "head": height - 0.1}
    kp = np.full((17, 3), np.nan)
    for side, dx in (("left", -0.12), ("right", 0.12)):
        for part in ("ankle", "knee", "hip", "shoulder"):
            kp[JOINT[f"{side}_{part}"]] = [x + dx, y, z[part]]
    kp[JOINT["nose"]] = [x, y, z["head"]]
    pts = cam.project(np.nan_to_num(kp))
    pts[np.isnan(kp).any(axis=1)] = np.nan
    return pts


def test_court_position_from_ankles_and_from_legs(cam):
    kp = np.stack([person_at(cam, 3.0, 5.0), person_at(cam, 7.5, 16.0)])
    scores = np.where(np.isfinite(kp).all(axis=2), 0.9, 0.0)
    np.testing.assert_allclose(court_positions(kp, scores, cam), [[3.0, 5.0], [7.5, 16.0]], atol=1e-6)
    no_ankles = scores.copy()
    no_ankles[:, [JOINT["left_ankle"], JOINT["right_ankle"]]] = 0.1  # below the confidence threshold
    np.testing.assert_allclose(court_positions(kp, no_ankles, cam), [[3.0, 5.0], [7.5, 16.0]], atol=0.3)
    nothing = np.zeros_like(scores)
    assert np.isnan(court_positions(kp, nothing, cam)).all()


def test_foot_above_the_horizon_is_unknown(cam):
    kp = np.full((1, 17, 2), np.nan)
    kp[0, [JOINT["left_ankle"], JOINT["right_ankle"]]] = [[640, 5], [650, 5]]  # near the top: sky
    sky = Camera.from_look_at([5.0, -3.0, 6.0], [5.0, 9.5, 8.0], (W, H), fov_deg=80)  # looking up
    assert np.isfinite(foot_points(kp, np.ones((1, 17)))).all()
    assert np.isnan(court_positions(kp, np.ones((1, 17)), sky)).all()


@pytest.fixture(scope="module")
def padel():
    return Clip(SAMPLE / "padel_sample")


def run_pipeline(clip, noise=DetectionNoise(), seed=0, tmp=None):
    gt = clip.read_players(gt=True)
    cam = clip.read_camera(gt=True)
    seq = simulate_detections(gt, clip.n_frames, cam.image_size, np.random.default_rng(seed), noise)
    if tmp is not None:  # through the importer path, as MMPose JSON
        from inference.players.importers import load_predictions, write_mmpose_json

        write_mmpose_json(tmp / "preds.json", seq)
        seq = load_predictions(tmp / "preds.json", n_frames=clip.n_frames)
    pred = players_from_poses(seq, cam, load_court(clip.court_path()), clip.info.fps)
    return pred, gt


def test_tracking_keeps_identities_and_positions(padel, tmp_path):
    pred, gt = run_pipeline(padel, tmp=tmp_path)
    s = score(pred, gt, padel.info.fps)
    assert pred.ids() == [0, 1, 2, 3]
    assert s.switches == 0 and s.median_error_m <= 0.15 and s.coverage > 0.9
    teams = {pid: pred.of_player(pid).team[0] for pid in pred.ids()}
    assert teams == {0: "near", 1: "near", 2: "far", 3: "far"}


def test_spectators_and_extra_candidates_are_not_players(padel):
    noise = DetectionNoise(spectators=6)
    pred, gt = run_pipeline(padel, noise, seed=1)
    assert len(pred.ids()) == 4
    assert np.all(np.abs(np.nanmedian(pred.court_xy, axis=0)) < 25)
    for pid in pred.ids():
        xy = np.nanmedian(pred.of_player(pid).court_xy, axis=0)
        assert -1.5 <= xy[0] <= 11.5 and -1.5 <= xy[1] <= 21.5


def test_empty_frames_give_no_players(padel):
    seq = PoseSequence([Persons.empty() for _ in range(30)])
    pred = players_from_poses(seq, padel.read_camera(gt=True), load_court("padel"), 30.0)
    assert len(pred) == 0


def test_keypoints_outside_the_frame_are_tolerated(cam):
    frames = []
    for f in range(40):
        kp = person_at(cam, 2.0 + 0.05 * f, 4.0)[None]
        kp[0, JOINT["nose"]] = [-50.0, -80.0]  # a joint predicted outside the image
        frames.append(Persons(np.full((1, 4), np.nan), kp, np.full((1, 17), 0.9), np.array([0.9])))
    pred = players_from_poses(PoseSequence(frames), cam, load_court("padel"), 30.0)
    assert pred.ids() == [0]
    np.testing.assert_allclose(pred.court_xy[-1], [2.0 + 0.05 * 39, 4.0], atol=0.05)


def test_backend_errors_name_what_is_missing(tmp_path):
    with pytest.raises(BackendUnavailable, match="--predictions"):
        make_backend("import")
    ok, reason = make_backend("rtmpose", pose_model=tmp_path / "p.onnx", det_model=tmp_path / "d.onnx").available()
    assert not ok and ("onnxruntime" in reason or "p.onnx" in reason)
    ok, reason = make_backend("movenet", model=tmp_path / "m.tflite").available()
    assert not ok and ("ai-edge-litert" in reason or "m.tflite" in reason)
    with pytest.raises(ValueError, match="unknown pose backend"):
        make_backend("openpifpaf")


def test_decode_movenet_output():
    raw = np.zeros((6, 56))
    raw[0, :51] = np.tile([0.5, 0.25, 0.9], 17)          # every joint at (y=0.5, x=0.25) of the canvas
    raw[0, 51:56] = [0.4, 0.2, 0.6, 0.3, 0.8]            # box and score
    p = decode_movenet(raw, (288, 512), scale=0.4)
    assert len(p) == 1
    np.testing.assert_allclose(p.keypoints[0, 0], [0.25 * 512 / 0.4, 0.5 * 288 / 0.4])
    np.testing.assert_allclose(p.boxes[0], [0.2 * 512 / 0.4, 0.4 * 288 / 0.4, 0.3 * 512 / 0.4, 0.6 * 288 / 0.4])


def test_cli_players(tmp_path, padel, capsys):
    from inference.players.importers import write_mmpose_json

    clip_dir = tmp_path / "clip"
    shutil.copytree(SAMPLE / "padel_sample", clip_dir)
    shutil.copy(clip_dir / "gt" / "camera.yaml", clip_dir / "camera.yaml")
    gt = padel.read_players(gt=True)
    seq = simulate_detections(gt, padel.n_frames, (W, H), np.random.default_rng(2))
    write_mmpose_json(tmp_path / "preds.json", seq)
    assert main(["players", str(clip_dir), "--pose", "import", "--predictions", str(tmp_path / "preds.json")]) == 0
    assert "4 players" in capsys.readouterr().out
    assert Clip(clip_dir).read_players().ids() == [0, 1, 2, 3]
    assert main(["players", str(clip_dir), "--pose", "rtmpose", "--pose-model", str(tmp_path / "x.onnx"),
                 "--det-model", str(tmp_path / "y.onnx")]) == 1
    err = capsys.readouterr().err
    assert "rtmpose" in err and ("onnxruntime" in err or "x.onnx" in err)


def test_movenet_backend_on_rendered_players():
    """The offline default backend (installed by make) finds the rendered tennis players."""
    from inference.players.backends import MoveNetBackend

    backend = MoveNetBackend()
    ok, reason = backend.available()
    if not ok:
        pytest.skip(reason)
    clip = Clip(SAMPLE / "tennis_sample")
    gt = clip.read_players(gt=True)
    frames = clip.frames()
    errors = []
    for f in (0, 40, 80):
        persons = backend.infer(frames[f])
        assert (persons.scores > 0.2).sum() >= 2
        for g in gt.keypoints[gt.frame == f, :, :2] * [clip.info.width, clip.info.height]:
            errors.append(np.nanmean(np.linalg.norm(persons.keypoints - g[None], axis=2), axis=1).min())
    assert np.median(errors) < 15.0


def test_movenet_input_size_grows_with_the_frame():
    """1080p frames run MoveNet at a 960-px input (far players stay large enough), smaller frames at 640."""
    import cv2

    from inference.players.backends import MoveNetBackend, movenet_input_size

    assert movenet_input_size(1080, 1920) == 960 and movenet_input_size(720, 1280) == 640
    assert movenet_input_size(1080, 1920, 640) == 640
    backend = MoveNetBackend()
    ok, reason = backend.available()
    if not ok:
        pytest.skip(reason)
    clip = Clip(SAMPLE / "tennis_sample")
    frame = clip.frames()[40]
    gt = clip.read_players(gt=True)
    big = cv2.resize(frame, (1920, 1080))
    persons = backend.infer(big)
    assert backend._shape == (544, 960)                       # 1080 × 960 / 1920 = 540 → 544
    sx, sy = 1920 / clip.info.width, 1080 / clip.info.height
    for g in gt.keypoints[gt.frame == 40, :, :2] * [clip.info.width * sx, clip.info.height * sy]:
        assert np.nanmean(np.linalg.norm(persons.keypoints - g[None], axis=2), axis=1).min() < 25.0
    backend.infer(frame)
    assert max(backend._shape) == 640


def _persons(cam, spots, scores):
    """Persons standing at court ``spots`` [(x, y), ...] with person ``scores``; boxes from their keypoints."""
    kps = np.stack([person_at(cam, x, y) for x, y in spots]) if spots else np.zeros((0, 17, 2))
    return Persons(np.full((len(spots), 4), np.nan), kps, np.where(np.isfinite(kps).all(axis=2), 0.9, 0.0),
                   np.asarray(scores, float))


def test_a_chosen_players_track_is_carried_onto_the_weak_detections_at_its_ends(cam):
    """The tracker confirms a track a look late and drops a player whose detection turns weak (running out of
    the picture, under a score box): the chosen players' tracks are carried onto detections overlapping their end
    box — not onto a detection another player holds, nor onto one that does not overlap."""
    from inference.players.tracking import Track, TrackingConfig, extend_ends

    court = load_court("padel")
    n = 24
    walk = {f: (3.0 + 0.05 * f, 4.0) for f in range(15)}       # a near player walking slowly along the net, gone
    frames = []                                                  # after frame 14 (out of the picture)
    for f in range(n):
        spots, sc = [], []
        if f in walk:
            spots.append(walk[f]); sc.append(0.8 if 4 <= f <= 12 else 0.12)  # weak before 4 and after 12
        if f >= 16:   # his team-mate steps where he was: tracked, and his own
            spots.append((3.75, 4.05)); sc.append(0.9)
        spots.append((8.5, 15.0)); sc.append(0.9)                # someone far away
        frames.append(_persons(cam, spots, sc))
    looked = np.zeros(n, bool)
    looked[::2] = True
    seq = PoseSequence(frames, "test", looked)

    def track(fs, k):
        p = [frames[f] for f in fs]
        return Track(np.array(fs), np.stack([q.boxes[k] for q in p]), np.stack([q.keypoints[k] for q in p]),
                     np.stack([q.kp_scores[k] for q in p]), np.array([q.scores[k] for q in p]),
                     court_positions(np.stack([q.keypoints[k] for q in p]), np.stack([q.kp_scores[k] for q in p]), cam))

    mate = track(list(range(16, n, 2)), 0)
    chosen = track([4, 6, 8, 10, 12], 0)
    out = extend_ends([chosen, mate], seq, cam, 25.0, TrackingConfig(extend_s=0.5))
    # carried back to frame 0 and on to frame 14; frame 16's detection on his spot is the team-mate's
    assert out[0].frames.tolist() == [0, 2, 4, 6, 8, 10, 12, 14], out[0].frames
    np.testing.assert_allclose(out[0].court[0], walk[0], atol=0.05)
    assert out[1].frames.tolist() == mate.frames.tolist()      # nobody overlaps the team-mate before frame 16
    # without the team-mate's track the detection on the spot would be taken: the test above is not vacuous
    assert 16 in extend_ends([chosen], seq, cam, 25.0, TrackingConfig(extend_s=0.5))[0].frames.tolist()
    # the far person never overlaps the near player: no continuation there
    assert not (np.isin(out[0].frames, [0, 2, 14]) & (out[0].court[:, 1] > 10)).any()
