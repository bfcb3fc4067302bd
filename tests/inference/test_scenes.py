"""Scenes (the stretches between the editor's cuts) of a broadcast-like clip: the padel sample with a close-up and another camera's footage (the tennis
sample) spliced in. Cuts are found at the right frames, court views are told apart with and without a
camera, `rally3d infer` searches the court-view frames only, and a clip folder from before scenes.json had its
name (shots.json) is still read."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from inference.camera import Camera
from inference.clipio import Clip, FormatError, FrameSource, write_video
from inference.court import load_court
from inference.video.scenes import LEGACY_FILE, Scene, SceneReport, find_scenes, scenes_file

SAMPLE = Path(__file__).resolve().parents[2] / "datasets" / "sample"
CLOSEUP, OTHER = (80, 120), (160, 190)  # frames replaced by a close-up and by another camera
BOUNDS = [0, 80, 120, 160, 190, 240]


def closeup(frame: np.ndarray, zoom: float = 2.5, centre=(640, 420)) -> np.ndarray:
    h, w = frame.shape[:2]
    m = np.float32([[zoom, 0, w / 2 - zoom * centre[0]], [0, zoom, h / 2 - zoom * centre[1]]])
    return cv2.warpAffine(frame, m, (w, h))


def splice(root: Path, first: int, n: int, close: tuple[int, int], other_span: tuple[int, int]) -> Clip:
    """Frames ``first .. first+n-1`` of the padel sample as a clip, with ``close`` (a close-up) and
    ``other_span`` (the tennis sample's camera) replaced; ball.csv keeps the padel ground truth."""
    shutil.copytree(SAMPLE / "padel_sample", root)
    with FrameSource.open(SAMPLE / "padel_sample" / "video.mp4") as a, \
            FrameSource.open(SAMPLE / "tennis_sample" / "video.mp4") as b:
        court, other = list(a.iter(first, first + n)), list(b.iter(20, 20 + other_span[1] - other_span[0]))
    frames = [closeup(f) if close[0] <= i < close[1] else other[i - other_span[0]]
              if other_span[0] <= i < other_span[1] else f for i, f in enumerate(court)]
    write_video(root / "video.mp4", frames, 30.0, fourcc="h264")
    clip = Clip(root)
    gt = clip.read_ball()
    keep = (gt.frame >= first) & (gt.frame < first + n)
    clip.write_ball(type(gt)(gt.frame[keep] - first, gt.visibility[keep], gt.xy[keep]))
    text = (root / "clip.yaml").read_text().replace("n_frames: 240", f"n_frames: {n}")
    (root / "clip.yaml").write_text(text)
    return Clip(root)


@pytest.fixture(scope="module")
def spliced(tmp_path_factory) -> Clip:
    return splice(tmp_path_factory.mktemp("scenes") / "broadcast", 0, 240, CLOSEUP, OTHER)


def _spans(report: SceneReport) -> list[int]:
    return [s.start for s in report.scenes] + [report.n_frames]


def test_cuts_and_court_views_from_the_calibrated_court_lines(spliced):
    report = find_scenes(spliced, Camera.load(SAMPLE / "padel_sample" / "gt" / "camera.yaml"), load_court("padel"))
    assert _spans(report) == BOUNDS, report.table()
    assert [s.court_view for s in report.scenes] == [True, False, True, False, True], report.table()
    assert {s.how for s in report.scenes} == {"court lines"}
    active = report.active()
    assert not active[80:120].any() and not active[160:190].any() and active[:80].all() and active[190:].all()
    assert "70 frames outside court views left out (frames 80–119, 160–189)" in report.summary()


def test_without_a_camera_the_main_view_is_the_longest_scene(spliced):
    report = find_scenes(spliced)
    assert _spans(report) == BOUNDS
    assert [s.court_view for s in report.scenes] == [True, False, True, False, True], report.table()
    assert {s.how for s in report.scenes} == {"similarity"}


def test_a_clip_without_cuts_is_one_court_view():
    report = find_scenes(Clip(SAMPLE / "padel_sample"), Camera.load(SAMPLE / "padel_sample" / "gt" / "camera.yaml"),
                         load_court("padel"))
    assert len(report.scenes) == 1 and report.active().all() and report.n_frames == 240


def test_scenes_json_round_trip_and_bad_files(tmp_path, spliced):
    report = find_scenes(spliced)
    path = report.write(tmp_path / "scenes.json")
    again = SceneReport.read(path)
    assert again.scenes == report.scenes and again.n_frames == 240
    data = json.loads(path.read_text())
    assert "scenes" in data and "shots" not in data
    data["scenes"][1]["start"] = 85  # a gap between scenes
    path.write_text(json.dumps(data))
    with pytest.raises(FormatError, match=r"scenes.json.*without gaps.*fix: delete scenes.json"):
        SceneReport.read(path)
    path.write_text('{"scenes": [{"start": 0}]}')
    with pytest.raises(FormatError, match="not a scenes file"):
        SceneReport.read(path)


def _legacy_file(root: Path, report: SceneReport) -> Path:
    """What rally3d infer wrote before scenes.json had its name: shots.json, its list called "shots"."""
    d = report.to_dict()
    d["shots"] = d.pop("scenes")
    path = root / LEGACY_FILE
    path.write_text(json.dumps(d))
    return path


def test_a_folder_from_before_scenes_json_is_still_read(tmp_path):
    """A clip folder with only the old shots.json: scenes_file finds it and SceneReport.read reads it; once a
    scenes.json is there, that one wins; neither: the path of scenes.json (missing)."""
    assert scenes_file(tmp_path) == tmp_path / "scenes.json" and not scenes_file(tmp_path).exists()
    report = SceneReport([Scene(0, 80, True, 0.8, "court lines"), Scene(80, 120, False, 0.1, "court lines"),
                          Scene(120, 240, True, 0.7, "court lines")], 240, 30.0, ["a note"])
    old = _legacy_file(tmp_path, report)
    assert scenes_file(tmp_path) == old
    again = SceneReport.read(scenes_file(tmp_path))
    assert again.scenes == report.scenes and again.notes == ["a note"] and again.court_spans() == [(0, 80), (120, 240)]
    new = SceneReport([Scene(0, 240, True, 1.0, "single scene")], 240, 30.0).write(tmp_path / "scenes.json")
    assert scenes_file(tmp_path) == new and len(SceneReport.read(scenes_file(tmp_path)).scenes) == 1


def test_the_later_stages_read_an_old_folders_scenes(tmp_path, spliced):
    """``rally3d infer --only detect`` (or any later stage) on a folder from before the name: the court-view
    frames, cuts and spans come from its shots.json."""
    from inference.pipeline.stages import Context, PipelineConfig, _court_frames, _court_spans, _cut_frames
    from inference.pipeline.state import RunState

    clip = _broadcast(tmp_path, spliced, scenes=False)
    _legacy_file(clip.root, _views())
    ctx = Context(clip, load_court("padel"), PipelineConfig(progress=False), RunState(clip.root))
    assert np.array_equal(_court_frames(ctx), ~OFF)
    assert _cut_frames(ctx) == BOUNDS[1:-1]
    assert _court_spans(ctx) == [(0, 80), (120, 160), (190, 240)]


def test_the_scenes_stage_replaces_the_old_file(tmp_path, spliced):
    """The scenes stage on an old folder writes scenes.json and removes the shots.json the pipeline wrote; a
    shots.json it did not write (made by hand) is kept and the stage says how to keep or replace it; with
    --overwrite it is replaced, a backup kept."""
    from inference.pipeline.run import run_pipeline
    from inference.pipeline.stages import PipelineConfig
    from inference.pipeline.state import RunState

    def scenes_stage(clip, **cfg):
        report = run_pipeline(clip, PipelineConfig(progress=False, pose="none", **cfg), only={"scenes"},
                              log=lambda *_: None)
        return next(s for s in report.stages if s.name == "scenes")

    clip = _broadcast(tmp_path / "by-hand", spliced, scenes=False)
    old = _legacy_file(clip.root, _views())
    stage = scenes_stage(clip)
    assert stage.status == "failed" and "former name of scenes.json" in stage.note and "--overwrite" in stage.note
    assert old.is_file() and not (clip.root / "scenes.json").exists()
    assert scenes_stage(clip, overwrite=True).status == "done"
    assert not old.exists() and len(list((clip.root / ".rally3d" / "backup").glob(f"{LEGACY_FILE}.*"))) == 1

    clip = _broadcast(tmp_path / "by-infer", spliced, scenes=False)
    old = _legacy_file(clip.root, _views())
    RunState(clip.root).record("shots", "key", "done", [old], 1.0)  # what the old pipeline recorded
    stage = scenes_stage(clip)
    assert stage.status == "done", stage
    assert not old.exists() and scenes_file(clip.root) == clip.root / "scenes.json"
    assert SceneReport.read(clip.root / "scenes.json").court_spans() == [(0, 80), (120, 160), (190, 240)]


def test_only_takes_the_former_stage_name(capsys):
    """``--only shots`` (the scenes stage's former name) still works, with a note; an unknown name does not."""
    from inference.pipeline.cli import STAGE_NAMES, _only_stages

    assert "scenes" in STAGE_NAMES and "shots" not in STAGE_NAMES
    assert _only_stages("shots,detect") == {"scenes", "detect"}
    assert "stage 'shots' is now called 'scenes'" in capsys.readouterr().err
    assert _only_stages("scenes") == {"scenes"} and capsys.readouterr().err == ""
    assert _only_stages(None) is None
    with pytest.raises(ValueError, match="unknown stages"):
        _only_stages("shot")


@pytest.mark.slow  # ~35 s CPU (the shipped WASB); the runner's `active` frames: test_detect.py, fast
def test_infer_searches_court_views_only(tmp_path, capsys):
    """The scenes and detect stages on a spliced clip of 100 frames (clicked court points → camera): frames
    of the close-up and the other camera come back unseen, the ball is still found in the court views."""
    from inference.pipeline.run import run_pipeline
    from inference.pipeline.stages import PipelineConfig

    clip = splice(tmp_path / "clip", 60, 100, (30, 50), (70, 85))
    gt = clip.read_ball()
    (clip.root / "ball.csv").unlink()  # the pipeline writes its own
    report = run_pipeline(clip, PipelineConfig(progress=False, pose="none"), only={"camera", "scenes", "detect",
                                                                                 "smooth"})
    status = {s.name: s.status for s in report.stages}
    assert status["scenes"] == status["detect"] == "done", report.table()
    out = capsys.readouterr().out
    assert "[scenes]" in out and "court view" in out
    scenes = SceneReport.read(clip.root / "scenes.json")
    assert _spans(scenes) == [0, 30, 50, 70, 85, 100]
    assert [s.court_view for s in scenes.scenes] == [True, False, True, False, True]
    ball = clip.read_ball()
    off = np.zeros(100, bool)
    off[30:50] = off[70:85] = True
    assert len(ball) == 100 and not (ball.visibility[off] > 0).any()
    seen = (ball.visibility > 0) & (gt.visibility > 0) & ~off
    px = np.linalg.norm((ball.xy[seen] - gt.xy[seen]) * [1280, 720], axis=1)
    assert seen.sum() > 0.5 * ((gt.visibility > 0) & ~off).sum() and np.median(px) < 5, (seen.sum(), np.median(px))
    assert "frames outside court views not searched" in next(s.note for s in report.stages if s.name == "detect")


# ----------------------------------------------------------------- events and 3D per court-view scene
OFF = np.zeros(240, bool)
OFF[CLOSEUP[0]:CLOSEUP[1]] = OFF[OTHER[0]:OTHER[1]] = True


def _views() -> SceneReport:
    """The spliced clip's scenes: court views but for the close-up and the other camera."""
    return SceneReport([Scene(a, b, not OFF[a], 1.0, "court lines") for a, b in zip(BOUNDS[:-1], BOUNDS[1:])],
                       240, 30.0)


def _broadcast(tmp_path: Path, spliced: Clip, scenes: bool = True) -> Clip:
    """The spliced clip with its camera, the padel ground truth's events and (``scenes``) its scenes.json.
    ball.csv keeps the padel ball in the close-up and the other camera's frames too — as a careless label
    or a tracker would — so only the scenes keep those frames out."""
    root = tmp_path / "clip"
    shutil.copytree(spliced.root, root)
    shutil.copy(SAMPLE / "padel_sample" / "gt" / "camera.yaml", root / "camera.yaml")
    if scenes:
        _views().write(root / "scenes.json")
    return Clip(root)


def test_events_are_decoded_per_court_view_scene(tmp_path, spliced):
    """The shipped hit-event model on the labelled ball: no event in the close-up or the other camera's frames
    (the ball.csv has the ball there), the court views' events still found."""
    from inference.pipeline.run import run_pipeline
    from inference.pipeline.stages import PipelineConfig

    clip = _broadcast(tmp_path, spliced)
    gt = clip.read_events()
    report = run_pipeline(clip, PipelineConfig(progress=False, pose="none", overwrite=True), only={"events"})
    stage = next(s for s in report.stages if s.name == "events")
    assert stage.status == "done" and "in 3 court-view scenes" in stage.note, report.table()
    ev = clip.read_events()
    assert len(ev) and not OFF[ev.frame].any(), ev.frame
    court_gt = gt.frame[~OFF[gt.frame]]
    found = [np.min(np.abs(ev.frame - f)) <= 3 for f in court_gt]
    assert np.mean(found) >= 0.7, (ev.frame, court_gt)


def test_3d_fit_never_joins_frames_across_a_cut(tmp_path, spliced):
    """Ground-truth ball and events: every flight lies inside one court-view scene, frames outside court views
    have no 3D and segments.json says why; the court views are reconstructed close to the ground truth.
    Without scenes.json the same clip gets flights across the cuts (what the scenes prevent)."""
    from inference.clipio import read_ball_3d_csv
    from inference.pipeline.per_scene import LEFT_OUT
    from inference.pipeline.run import run_pipeline
    from inference.pipeline.stages import PipelineConfig

    clip = _broadcast(tmp_path, spliced)
    report = run_pipeline(clip, PipelineConfig(progress=False, pose="none"), only={"reconstruct"})
    stage = next(s for s in report.stages if s.name == "reconstruct")
    assert stage.status == "done" and "3 court-view scenes fitted apart" in stage.note, report.table()
    seg = json.loads(clip.segments_path.read_text())
    views = [(a, b) for a, b in zip(BOUNDS[:-1], BOUNDS[1:]) if not OFF[a]]
    ok = [s for s in seg["segments"] if s["reconstructed"]]
    assert len(ok) >= 8
    for s in seg["segments"]:
        assert any(a <= s["start_frame"] <= s["end_frame"] < b for a, b in views), s
    left = [e for e in seg["scenes"] if not e["court_view"]]
    assert [(e["start_frame"], e["end_frame"]) for e in left] == [(80, 119), (160, 189)]
    assert {e["reason"] for e in left} == {LEFT_OUT}
    b3 = clip.read_ball_3d()
    assert len(b3) > 100 and not OFF[b3.frame].any()
    truth = read_ball_3d_csv(SAMPLE / "padel_sample" / "gt" / "ball_3d.csv")
    xyz = dict(zip(truth.frame.tolist(), truth.xyz))
    err = np.array([np.linalg.norm(p - xyz[f]) for f, p in zip(b3.frame.tolist(), b3.xyz) if f in xyz])
    assert np.median(err) < 0.3, np.median(err)

    whole = _broadcast(tmp_path / "whole", spliced, scenes=False)
    run_pipeline(whole, PipelineConfig(progress=False, pose="none"), only={"reconstruct"})
    across = [s for s in json.loads(whole.segments_path.read_text())["segments"]
              if not any(a <= s["start_frame"] <= s["end_frame"] < b for a, b in views)]
    assert across  # the flights over the close-up and the other camera


def test_one_scene_clip_reconstructs_as_without_scenes(tmp_path, spliced):
    """A scenes.json of one court view changes nothing: the same flights and 3D as with no scenes.json."""
    from inference.pipeline.run import run_pipeline
    from inference.pipeline.stages import PipelineConfig

    out = {}
    for name in ("none", "one"):
        clip = _broadcast(tmp_path / name, spliced, scenes=False)
        if name == "one":
            SceneReport([Scene(0, 240, True, 1.0, "single scene")], 240, 30.0).write(clip.root / "scenes.json")
        run_pipeline(clip, PipelineConfig(progress=False, pose="none"), only={"reconstruct"})
        seg = json.loads(clip.segments_path.read_text())
        out[name] = ([{k: v for k, v in s.items()} for s in seg["segments"]], "scenes" in seg, clip.read_ball_3d())
    assert out["none"][0] == out["one"][0] and not out["one"][1]
    assert out["none"][2] == out["one"][2]


def test_scene_frames_and_rows_renumber_a_scene_from_zero(spliced):
    """What a crop event model and the per-scene stages read of scene 120–159: its own frames and rows from 0."""
    from inference.pipeline.per_scene import SceneFrames
    from inference.video.scenes import scene_rows

    with spliced.frames(cache_size=0) as src:
        scene = SceneFrames(src, 120, 160)
        frames = list(scene.iter(0, 100))
        assert len(scene) == len(frames) == 40
        assert np.array_equal(frames[5], src.read(125)) and np.array_equal(scene.read(39), src.read(159))
    ball = spliced.read_ball()
    rows = scene_rows(ball, 120, 160)
    assert rows.frame.tolist() == list(range(40))
    assert np.array_equal(rows.xy, ball.xy[(ball.frame >= 120) & (ball.frame < 160)], equal_nan=True)
    ev = scene_rows(spliced.read_events(), 120, 160)
    assert ev.frame.tolist() == [14, 27] and list(ev.event) == ["ground", "player_far"]
