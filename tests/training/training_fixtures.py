"""Fixtures and helpers of the training tests (imported: ``from training_fixtures import …``; a second conftest.py
would clash with tests/conftest.py): Hydra configs composed as train.py / eval.py would, and a dataset built
the way annotators leave it (the labeler's clip folders, no manifest)."""
from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from conftest import compose_cfg

from inference.clipio import BallTrack, Clip, write_video
from synth.generate import SynthConfig, generate_clip

ROOT = Path(__file__).resolve().parents[2]


def _resize_video(clip: Clip, size: tuple[int, int]) -> None:
    """Re-encode the clip's video at another size (coordinates are normalised: ball.csv stays right)."""
    with clip.frames(cache_size=0) as src:
        frames = [cv2.resize(f, size, interpolation=cv2.INTER_AREA) for f in src.iter()]
    write_video(clip.video_path, iter(frames), clip.info.fps, fourcc="mp4v")
    info = clip.info
    info.width, info.height = size
    clip.write_info(info)


def make_labeler_dataset(root: Path) -> dict[str, str]:
    """Clip folders as annotators leave them, under ``root`` (no manifest.yaml, no gt/, no split):

    - ``a_25fps`` 25 fps, 320×180; an unlabelled gap (frames 20–25, no rows) and an occluded frame (3);
    - ``b_partial`` 50 fps, 1280×720 (re-encoded); labelled on its first 18 frames only (a partial label);
    - ``c_60fps_4k`` 60 fps, 3840×2160 (re-encoded, short); a real tracker's ball.csv: rows only where it
      saw the ball; no events.csv (events not labelled yet); same ``match`` as ``d_30fps``;
    - ``d_30fps`` 30 fps, 256×144; complete;
    - ``e_unlabelled`` 30 fps: no ball.csv at all (not labelled yet).
    Returns the notes per clip (what each stands for).
    """
    specs = {
        "a_25fps": dict(fps=25.0, width=320, height=180, max_frames=48, seed=11),
        "b_partial": dict(fps=50.0, width=320, height=176, max_frames=48, seed=12, resize=(1280, 720)),
        "c_60fps_4k": dict(fps=60.0, width=320, height=180, max_frames=24, seed=13, resize=(3840, 2160)),
        "d_30fps": dict(fps=30.0, width=256, height=144, max_frames=48, seed=14),
        "e_unlabelled": dict(fps=30.0, width=256, height=144, max_frames=24, seed=15),
    }
    root.mkdir(parents=True, exist_ok=True)
    for name, s in specs.items():
        generate_clip(root / name, s["seed"], SynthConfig(sport="padel", randomise_camera=False, fps=s["fps"],
                                                          width=s["width"], height=s["height"], codec="mp4v",
                                                          randomise_look=False, max_frames=s["max_frames"]))
        clip = Clip(root / name)
        if "resize" in s:
            _resize_video(clip, s["resize"])
        shutil.rmtree(clip.gt_dir)          # real clips have no ground truth
        for extra in ("inactive_balls.csv", "court_points.csv"):
            (clip.root / extra).unlink(missing_ok=True)
        info = clip.info
        info.split = None
        info.extra = {"match": "club_final"} if name in ("c_60fps_4k", "d_30fps") else {}
        clip.write_info(info)
    a = Clip(root / "a_25fps").read_ball()
    keep = (a.frame < 20) | (a.frame >= 26)
    vis = a.visibility.copy()
    vis[np.flatnonzero((a.frame >= 30) & (vis > 0))[0]] = 3  # an occluded ball the annotator placed
    Clip(root / "a_25fps").write_ball(BallTrack(a.frame[keep], vis[keep], a.xy[keep]))
    b = Clip(root / "b_partial").read_ball()
    Clip(root / "b_partial").write_ball(BallTrack(b.frame[:18], b.visibility[:18], b.xy[:18]))
    c = Clip(root / "c_60fps_4k").read_ball()
    seen = c.visibility > 0
    Clip(root / "c_60fps_4k").write_ball(BallTrack(c.frame[seen], c.visibility[seen], c.xy[seen]))
    (root / "c_60fps_4k" / "events.csv").unlink()
    (root / "e_unlabelled" / "ball.csv").unlink()
    assert not (root / "manifest.yaml").exists()
    return {"a_25fps": "gap + occluded", "b_partial": "partial, 720p", "c_60fps_4k": "tracker rows, 4K, no events",
            "d_30fps": "complete", "e_unlabelled": "no ball.csv"}


@pytest.fixture(scope="session")
def labeler_clips(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("labeler") / "my_clips"
    make_labeler_dataset(root)
    return root


@pytest.fixture(scope="session")
def tiny_padel(tmp_path_factory) -> Path:
    """Three short synthetic padel clips with a manifest (train, val, test)."""
    from synth.generate import generate_dataset

    root = tmp_path_factory.mktemp("tinyset") / "synth_padel"
    generate_dataset(root, 3, seed=5, config=SynthConfig(sport="padel", randomise_camera=False, width=320,
                                                         height=192, fps=30.0, codec="mp4v", randomise_look=False,
                                                         max_frames=40))
    return root


def small_detector(root, cache: Path) -> list[str]:
    """Overrides that make a detector run tiny (net 64×112, crops 32×32, batch 2, CPU)."""
    roots = root if isinstance(root, str) else str(root)
    return [f"data.root={roots}", "data.net_size=[64,112]", "data.crop=[32,32]", "data.batch_size=2",
            "trainer.accelerator=cpu", f"data.cache_dir={cache}", "callbacks.progress_log.every_n_steps=1"]


__all__ = ["ROOT", "compose_cfg", "labeler_clips", "make_labeler_dataset", "small_detector", "tiny_padel"]
