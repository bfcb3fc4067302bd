"""Posing every N-th frame: the frames looked at, the tracker on them, the players filled between."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from inference.clipio import Clip
from inference.court import load_court
from inference.players import Persons, PoseSequence
from inference.players.backends import _FrameBackend
from inference.players.evaluate import DetectionNoise, score, simulate_detections
from inference.players.sampling import pose_stride
from inference.players.tracking import players_from_poses
from inference.players.sampling import sampled_frames

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample"


@pytest.fixture(scope="module")
def padel():
    return Clip(SAMPLE / "padel_sample")


def test_sampled_frames_keep_the_grid_and_the_last_frame():
    assert np.flatnonzero(sampled_frames(10, 3)).tolist() == [0, 3, 6, 9]
    assert np.flatnonzero(sampled_frames(8, 3)).tolist() == [0, 3, 6, 7]
    assert sampled_frames(5, 1).all() and not sampled_frames(0, 2).size
    with pytest.raises(ValueError, match="stride"):
        sampled_frames(5, 0)


def test_pose_stride_from_the_frame_rate():
    assert [pose_stride(f) for f in (12, 25, 30, 50, 60)] == [1, 2, 2, 3, 4]
    assert pose_stride(25, every=1) == 1 and pose_stride(25, every=3) == 3


class CountingBackend(_FrameBackend):
    """A pose 'model' that records which frames it was shown (the frame's mean brightness as its id)."""

    name = "counting"

    def __init__(self):
        self.calls = 0

    def available(self):
        return True, ""

    def infer(self, image):
        self.calls += 1
        return Persons.empty()


def test_backend_poses_only_the_frames_of_its_stride_inside_the_court_views(padel):
    n = padel.n_frames
    active = np.ones(n, bool)
    active[100:140] = False  # a replay: not searched
    backend = CountingBackend()
    seq = backend.run(padel, progress=False, active=active, stride=3)
    expected = sum(int(sampled_frames(b - a, 3).sum()) for a, b in ((0, 100), (140, n)))
    assert backend.calls == expected < n // 2
    assert seq.looked is not None and len(seq.looked) == n
    assert seq.looked[0] and seq.looked[99] and seq.looked[140] and seq.looked[n - 1] and not seq.looked[1]
    assert seq.looked[100:140].any()  # empty looks on the grid over the replay: the tracker sees the cut
    every = CountingBackend()
    assert every.run(padel, progress=False).looked is None and every.calls == n


def strided(seq: PoseSequence, stride: int) -> PoseSequence:
    look = sampled_frames(len(seq), stride)
    return PoseSequence([p if look[i] else Persons.empty() for i, p in enumerate(seq.frames)], seq.source, look)


@pytest.mark.parametrize("stride", [2, 3])
def test_players_from_every_nth_pose_fill_every_frame(padel, stride):
    gt = padel.read_players(gt=True)
    cam = padel.read_camera(gt=True)
    court = load_court(padel.court_path())
    seq = simulate_detections(gt, padel.n_frames, cam.image_size, np.random.default_rng(0), DetectionNoise())
    full = score(players_from_poses(seq, cam, court, padel.info.fps), gt, padel.info.fps)
    pred = players_from_poses(strided(seq, stride), cam, court, padel.info.fps)
    s = score(pred, gt, padel.info.fps)
    assert pred.ids() == [0, 1, 2, 3] and s.switches == 0
    assert s.coverage > 0.9 and s.coverage >= full.coverage - 0.03  # the frames between the looks are filled
    assert s.median_error_m <= full.median_error_m + 0.05
    looked = sampled_frames(padel.n_frames, stride)
    filled = pred.score[~looked[pred.frame]]
    assert len(filled) and np.all(filled <= pred.score.max() * 0.5 + 1e-9)  # filled rows carry half the score


def test_an_ungridded_sequence_without_looks_is_tracked_on_every_frame(padel):
    """Without ``looked`` (every imported file) nothing changes: the tracker runs at the clip's rate."""
    gt = padel.read_players(gt=True)
    cam = padel.read_camera(gt=True)
    court = load_court(padel.court_path())
    seq = simulate_detections(gt, padel.n_frames, cam.image_size, np.random.default_rng(0), DetectionNoise())
    a = players_from_poses(seq, cam, court, padel.info.fps)
    b = players_from_poses(PoseSequence(seq.frames, seq.source, np.ones(len(seq), bool)), cam, court,
                           padel.info.fps)
    assert np.array_equal(a.frame, b.frame) and np.allclose(a.court_xy, b.court_xy, equal_nan=True)



def test_pose_every_is_checked_where_it_is_given(capsys):
    from inference.cli import main
    from inference.players.sampling import parse_pose_every
    from inference.pipeline.stages import PipelineConfig

    assert parse_pose_every("auto") == 0 and parse_pose_every("3") == 3
    with pytest.raises(ValueError, match="pose_every"):
        PipelineConfig(pose_every=-1)
    with pytest.raises(SystemExit):
        main(["infer", "nothing.mp4", "--pose-every", "0"])
    assert "expected auto or a whole number" in capsys.readouterr().err
