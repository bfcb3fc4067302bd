"""Every stage after ``scenes`` leaves the frames of scenes without the court alone: a generated tennis rally
with a cut to a zoomed close-up gets no player rows, no ball, no event and no 3D there — even from a pose
backend and a ball detector that report something in every frame of the clip (as real ones do in a close-up)."""
from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from inference.clipio import Clip, FrameSource, read_ball_csv, write_video
from inference.players.types import Persons, PoseSequence

N = 90
CLOSE = (40, 60)  # frames replaced by a close-up


def zoom(frame: np.ndarray, factor: float = 2.5) -> np.ndarray:
    """A close-up: the centre of ``frame`` magnified ``factor`` times."""
    h, w = frame.shape[:2]
    m = np.float32([[factor, 0, w / 2 * (1 - factor)], [0, factor, h / 2 * (1 - factor)]])
    return cv2.warpAffine(frame, m, (w, h))


@pytest.fixture(scope="module")
def rally(tmp_path_factory) -> Path:
    """A 640×360 tennis rally of 90 frames whose frames 40–59 are a close-up; camera.yaml given."""
    from synth.generate import SynthConfig, generate_clip

    root = tmp_path_factory.mktemp("court_views") / "rally"
    cfg = SynthConfig(sport="tennis", randomise_camera=False, fps=30.0, width=640, height=360, codec="mp4v",
                      max_frames=N)
    generate_clip(root, seed=33, config=cfg)
    with FrameSource.open(root / "video.mp4") as src:
        frames = [zoom(f) if CLOSE[0] <= i < CLOSE[1] else f for i, f in enumerate(src.iter())]
    write_video(root / "video.mp4", frames, 30.0, fourcc="mp4v")
    shutil.copy(root / "gt" / "camera.yaml", root / "camera.yaml")
    for name in ("ball.csv", "events.csv"):  # the pipeline writes its own (gt/ keeps the truth)
        shutil.copy(root / name, root / "gt" / name)
        (root / name).unlink()
    return root


class EveryFramePoses:
    """A pose backend that finds the generated players in every frame it is given, close-ups included."""

    name = "every-frame"

    def __init__(self, clip: Clip):
        self.truth = clip.read_players(gt=True)
        self.size = np.array([clip.info.width, clip.info.height], float)

    def available(self) -> tuple[bool, str]:
        return True, ""

    def run(self, clip: Clip, progress: bool = True, active: np.ndarray | None = None,
            stride: int = 1, focus=None) -> PoseSequence:
        frames = []  # every frame, whatever the stride: the tracker then runs at the clip's rate
        for f in range(clip.n_frames):
            m = self.truth.frame == f
            kp = self.truth.keypoints[m]
            frames.append(Persons(self.truth.bbox[m] * np.tile(self.size, 2), kp[..., :2] * self.size,
                                  np.nan_to_num(kp[..., 2]), np.full(int(m.sum()), 0.9)))
        return PoseSequence(frames, self.name)


class EveryFrameBall:
    """A ball detector that reports the generated ball in every frame, close-ups included."""

    engine = SimpleNamespace(name="every-frame")

    def __init__(self, truth):
        self.truth = truth

    def run(self, clip: Clip, progress: bool = False, tolerate_truncation: bool = False,
            active: np.ndarray | None = None):
        return SimpleNamespace(track=self.truth, n_frames=clip.n_frames, truncated=None)


def test_no_player_ball_event_or_3d_in_a_close_up(rally, tmp_path, monkeypatch):
    import inference.detection.detect as detect
    import inference.players.backends as backends
    from inference.pipeline.run import run_pipeline
    from inference.pipeline.stages import PipelineConfig
    from inference.video.scenes import Scene, SceneReport

    root = tmp_path / "clip"
    shutil.copytree(rally, root)
    clip = Clip(root)
    truth = read_ball_csv(root / "gt" / "ball.csv")
    monkeypatch.setattr(backends, "make_backend", lambda *a, **k: EveryFramePoses(clip))
    monkeypatch.setattr(detect.BallDetectorRunner, "from_weights",
                        classmethod(lambda cls, *a, **k: EveryFrameBall(truth)))
    report = run_pipeline(clip, PipelineConfig(progress=False, pose="every-frame"))
    status = {s.name: s.status for s in report.stages}
    done = ("scenes", "detect", "smooth", "players", "events")
    assert all(status[s] == "done" for s in done), report.table()

    scenes = SceneReport.read(root / "scenes.json")
    assert [(s.start, s.stop, s.court_view) for s in scenes.scenes] == \
        [(0, CLOSE[0], True), (*CLOSE, False), (CLOSE[1], N, True)], scenes.table()
    close = np.zeros(N, bool)
    close[CLOSE[0]:CLOSE[1]] = True

    players = clip.read_players()
    assert len(players) and not close[players.frame].any(), np.unique(players.frame[close[players.frame]])
    # the court views keep their players up to the cut and again from just after it (a track is confirmed
    # over two frames)
    assert set(players.frame) >= set(range(CLOSE[0] - 5, CLOSE[0])) | set(range(CLOSE[1] + 2, CLOSE[1] + 6))
    assert "20 frames outside court views not searched" in next(s.note for s in report.stages
                                                                 if s.name == "players")
    ball = clip.read_ball()
    seen = ball.visibility > 0
    assert seen.sum() > 0.5 * (~close).sum() and not (seen & close[ball.frame]).any()
    events = clip.read_events()
    assert not close[events.frame].any(), events.frame
    assert status["reconstruct"] == "done", report.table()
    assert len(clip.read_ball_3d()) and not close[clip.read_ball_3d().frame].any()

    # players.csv follows scenes.json: a new split re-runs the players stage
    SceneReport([scenes.scenes[0], Scene(CLOSE[0], N, True, 1.0, "court lines")], N, 30.0).write(root / "scenes.json")
    report = run_pipeline(clip, PipelineConfig(progress=False, pose="every-frame"), only={"players"})
    assert next(s.status for s in report.stages if s.name == "players") == "done", report.table()
    assert close[clip.read_players().frame].any()
