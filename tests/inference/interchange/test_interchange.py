"""CVAT for video 1.1 and Label Studio video JSON <-> clip folders: round trips, hand-written files in the
documented layouts, clear errors on bad input, safe XML, and the `rally3d import/export` commands."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from importlib.metadata import EntryPoint
from pathlib import Path

import numpy as np
import pytest

import inference.cli as cli
from inference.clipio import BallTrack, Clip, ClipInfo, FormatError, HitEvents
from inference.interchange.common import LabelMap, parse_xml
from inference.interchange.cvat import import_cvat
from inference.interchange.labelstudio import import_labelstudio

REPO = Path(__file__).resolve().parents[3]
SAMPLE = REPO / "datasets" / "sample" / "padel_sample"
COMMANDS = {
    "import": "inference.interchange.cli:register_import",
    "export": "inference.interchange.cli:register_export",
}


@pytest.fixture
def rally3d(monkeypatch):
    """`rally3d` with the import/export entry points (the shared venv may predate them)."""
    eps = [EntryPoint(name, value, cli.GROUP) for name, value in COMMANDS.items()]
    monkeypatch.setattr(cli, "entry_points", lambda group: eps if group == cli.GROUP else [])
    return cli.main


def test_entry_points_are_declared():
    text = (REPO / "pyproject.toml").read_text()
    section = text.split('[project.entry-points."rally3d.commands"]')[1].split("\n[")[0]
    for name, value in COMMANDS.items():
        assert f'\n{name} = "{value}"' in section


# ------------------------------------------------------------------------------------------- fixtures
def _awkward_clip(root: Path) -> Clip:
    """A 1920x1080 clip whose ball.csv has every case: gaps (not labelled), visibility 0-3, a run that
    starts hidden, one that ends hidden, one that ends hidden on the clip's last frame; and events."""
    clip = Clip.create(
        root, ClipInfo(sport="padel", fps=25.0, width=1920, height=1080, video="video.mp4", n_frames=60)
    )
    rows = (
        [(f, 1) for f in range(0, 6)]
        + [(6, 2), (7, 3), (8, 0), (9, 0), (10, 1), (11, 3)]  # run 0-11
        + [(20, 0), (21, 0), (22, 1), (23, 1), (24, 0)]  # hidden ends
        + [(30, 1)]  # one frame
        + [(40, 2), (41, 1), (42, 1), (43, 0)]  # hard, ends hidden
        + [(57, 1), (58, 1), (59, 0)]
    )  # to the last frame
    frame = [f for f, _ in rows]
    vis = [v for _, v in rows]
    rng = np.random.default_rng(3)
    xy = [[rng.uniform(0, 1), rng.uniform(0, 1)] if v else [np.nan, np.nan] for v in vis]
    xy[0] = [0.0, 1.0]  # on the image border
    clip.write_ball(BallTrack(frame, vis, xy))
    clip.write_events(
        HitEvents([3, 9, 22, 30, 45], ["player_near", "ground", "wall_left", "net", "player_far"])
    )
    return clip


@pytest.fixture(params=["awkward", "sample"])
def clip(request, tmp_path) -> Clip:
    if request.param == "sample":
        root = tmp_path / "padel_sample"
        root.mkdir()
        for name in ("clip.yaml", "ball.csv", "events.csv"):
            shutil.copy(SAMPLE / name, root / name)
        return Clip(root)
    return _awkward_clip(tmp_path / "awkward")


def _same_ball(a: BallTrack, b: BallTrack) -> None:
    np.testing.assert_array_equal(a.frame, b.frame)
    np.testing.assert_array_equal(a.visibility, b.visibility)
    np.testing.assert_allclose(a.xy, b.xy, atol=1e-6, equal_nan=True)  # 1e-6 of the width: < 0.002 px


# ---------------------------------------------------------------------------------------- round trips
@pytest.mark.parametrize("suffix", [".xml", ".json"])
def test_round_trip_through_the_commands(rally3d, clip, tmp_path, suffix, capsys):
    """clip folder -> export -> import into a new folder: the same ball rows and events."""
    out = tmp_path / f"labels{suffix}"
    assert rally3d(["export", str(clip.root), "--out", str(out)]) == 0
    new = tmp_path / "imported"
    # the new folder gets clip.yaml from the file (CVAT states the size; our LS export keeps it in meta)
    args = ["import", str(out), str(new), "--sport", "padel"] + (["--fps", "25"] if suffix == ".xml" else [])
    assert rally3d(args) == 0, capsys.readouterr().err
    back = Clip(new)
    _same_ball(clip.read_ball(), back.read_ball())
    assert back.read_events() == clip.read_events()
    assert (back.info.width, back.info.height, back.info.n_frames) == (
        clip.info.width,
        clip.info.height,
        clip.info.n_frames,
    )
    if suffix == ".json":
        assert back.info.fps == pytest.approx(clip.info.fps)
    # and once more into the same folder: refused without --overwrite, backed up with it
    assert rally3d(["import", str(out), str(new)]) == 1
    assert "--overwrite" in capsys.readouterr().err
    edited = (new / "ball.csv").read_text() + "\n"  # a hand edit since the first import
    (new / "ball.csv").write_text(edited)
    assert rally3d(["import", str(out), str(new), "--overwrite"]) == 0
    # the edited ball.csv is backed up; events.csv, identical to what is written, is left alone
    [copy] = (new / ".rally3d" / "backup").iterdir()
    assert copy.name.startswith("ball.csv.") and copy.read_text() == edited
    assert str(copy) in capsys.readouterr().out
    _same_ball(clip.read_ball(), back.read_ball())


def test_cvat_export_follows_cvat_conventions(clip, tmp_path):
    """Every row a keyframe (CVAT keeps only keyframes on upload); every run closed by an outside shape
    unless it reaches the last frame; events are one-frame tracks of their label."""
    from inference.interchange.cvat import export_cvat

    track, events = clip.read_ball(), clip.read_events()
    out = export_cvat(
        tmp_path / "a.xml",
        track,
        events,
        width=clip.info.width,
        height=clip.info.height,
        n_frames=clip.info.n_frames,
    )
    root = parse_xml(out)
    assert root.findtext("meta/task/original_size/width") == str(clip.info.width)
    balls = [t for t in root.findall("track") if t.attrib["label"] == "ball"]
    shapes = [s for t in balls for s in t.findall("points")]
    assert all(s.attrib["keyframe"] == "1" for s in shapes)
    n_runs = 1 + int(np.sum(np.diff(track.frame) > 1))
    assert len(balls) == n_runs
    rows = set(track.frame.tolist())
    closing = [
        t.findall("points")[-1] for t in balls if int(t.findall("points")[-1].attrib["frame"]) not in rows
    ]
    assert all(s.attrib["outside"] == "1" for s in closing)
    assert len(closing) == n_runs - int(track.frame[-1] == clip.info.n_frames - 1)
    event_tracks = [t for t in root.findall("track") if t.attrib["label"] != "ball"]
    assert [t.attrib["label"] for t in event_tracks] == events.event.tolist()


# ------------------------------------------------------------------------------ hand-written CVAT file
CVAT_META = """<?xml version="1.0" encoding="utf-8"?>
<annotations>
  <version>1.1</version>
  <meta>
    <task>
      <id>7</id><name>rally 7</name><size>{size}</size><mode>interpolation</mode>
      <start_frame>0</start_frame><stop_frame>{stop}</stop_frame><frame_filter></frame_filter>
      <labels><label><name>ball</name><type>points</type></label></labels>
      <original_size><width>1280</width><height>720</height></original_size>
    </task>
  </meta>
"""


def _cvat(tmp_path: Path, body: str, size: int = 30) -> Path:
    path = tmp_path / "annotations.xml"
    path.write_text(CVAT_META.format(size=size, stop=size - 1) + body + "</annotations>\n")
    return path


def test_cvat_handwritten_file_imports_to_expected_rows(tmp_path):
    """A file as an annotator leaves it: keyframes only (CVAT interpolates between them), occluded and
    outside keys, an ellipse track, a box track, a tag, an event drawn as a shape, an unknown label."""
    path = _cvat(
        tmp_path,
        """
  <track id="0" label="ball" source="manual">
    <points frame="0" keyframe="1" outside="0" occluded="0" points="100.00,200.00" z_order="0"/>
    <points frame="4" keyframe="1" outside="0" occluded="1" points="140.00,240.00" z_order="0"/>
    <points frame="5" keyframe="1" outside="0" occluded="0" points="150.00,250.00" z_order="0">
      <attribute name="visibility">2</attribute>
    </points>
    <points frame="6" keyframe="1" outside="1" occluded="0" points="150.00,250.00" z_order="0"/>
    <points frame="9" keyframe="1" outside="0" occluded="0" points="640.00,360.00" z_order="0"/>
    <points frame="10" keyframe="1" outside="1" occluded="0" points="640.00,360.00" z_order="0"/>
  </track>
  <track id="1" label="ball" source="manual">
    <ellipse frame="15" keyframe="1" outside="0" occluded="0" cx="1280.00" cy="0.00" rx="5.00" ry="5.00"/>
    <ellipse frame="16" keyframe="1" outside="1" occluded="0" cx="1280.00" cy="0.00" rx="5.00" ry="5.00"/>
  </track>
  <track id="2" label="ball" source="manual">
    <box frame="20" keyframe="1" outside="0" occluded="0" xtl="10.00" ytl="20.00" xbr="30.00" ybr="40.00"/>
  </track>
  <track id="3" label="player_near" source="manual">
    <points frame="4" keyframe="1" outside="0" occluded="0" points="140.00,240.00" z_order="0"/>
    <points frame="5" keyframe="1" outside="1" occluded="0" points="140.00,240.00" z_order="0"/>
  </track>
  <track id="4" label="player" source="manual">
    <box frame="0" keyframe="1" outside="0" occluded="0" xtl="1" ytl="1" xbr="9" ybr="9" z_order="0"/>
  </track>
  <tag frame="9" label="ground" source="manual"/>
""",
    )
    got = import_cvat(path)
    expected_frames = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 15, 20]
    expected_vis = [1, 1, 1, 1, 3, 2, 0, 0, 0, 1, 1, 1]
    np.testing.assert_array_equal(got.ball.frame, expected_frames)
    np.testing.assert_array_equal(got.ball.visibility, expected_vis)
    px = got.ball.to_pixels(1280, 720)
    np.testing.assert_allclose(
        px[:6], [[100, 200], [110, 210], [120, 220], [130, 230], [140, 240], [150, 250]]
    )
    assert np.isnan(px[6:9]).all()
    np.testing.assert_allclose(px[9:], [[640, 360], [1280, 0], [20, 30]])
    assert got.events == HitEvents([4, 9], ["player_near", "ground"])
    assert (got.width, got.height, got.n_frames) == (1280, 720, 30)
    assert any("'player'" in w and "--label-map" in w for w in got.warnings)
    assert any("ends on a visible keyframe" in w for w in got.warnings)  # track 2 has no closing outside


def test_cvat_label_map_and_frame_step(tmp_path):
    body = """
  <track id="0" label="pelota"><points frame="10" keyframe="1" outside="0" occluded="0" points="64,36"/>
    <points frame="14" keyframe="1" outside="0" occluded="0" points="64,72"/></track>
  <tag frame="12" label="bounce" source="manual"/>
"""
    path = _cvat(tmp_path, body.replace("\n", "\n"))
    text = (
        path.read_text()
        .replace("<start_frame>0</start_frame>", "<start_frame>10</start_frame>")
        .replace("<frame_filter></frame_filter>", "<frame_filter>step=2</frame_filter>")
    )
    path.write_text(text)
    got = import_cvat(path, LabelMap.parse(["pelota=ball", "bounce=ground"]))
    np.testing.assert_array_equal(got.ball.frame, [0, 1, 2])  # video frames 10, 12, 14
    np.testing.assert_allclose(got.ball.xy[:, 1], [0.05, 0.075, 0.1])
    assert got.events == HitEvents([1], ["ground"])
    with pytest.raises(ValueError, match="did you mean 'ground'"):
        LabelMap.parse(["bounce=grund"])


# ------------------------------------------------------------------------ hand-written Label Studio file
def _ls_task(result: list, task_id: int = 1) -> dict:
    return {
        "id": task_id,
        "data": {"video": "/data/upload/1/rally.mp4"},
        "annotations": [{"id": 11, "was_cancelled": False, "result": result}],
    }


def _box(seq: list, labels=("ball",)) -> dict:
    return {
        "id": "b1",
        "type": "videorectangle",
        "from_name": "box",
        "to_name": "video",
        "origin": "manual",
        "value": {"framesCount": 50, "duration": 2.0, "labels": list(labels), "sequence": seq},
    }


def _timeline(label: str, ranges: list) -> dict:
    return {
        "id": f"t{label}",
        "type": "timelinelabels",
        "from_name": "events",
        "to_name": "video",
        "value": {"ranges": [{"start": a, "end": b} for a, b in ranges], "timelinelabels": [label]},
    }


def _kf(frame, x, y, enabled=True, w=2.0, h=4.0):
    return {
        "frame": frame,
        "enabled": enabled,
        "rotation": 0,
        "x": x,
        "y": y,
        "width": w,
        "height": h,
        "time": (frame - 1) / 25,
    }


def test_labelstudio_handwritten_file_imports_to_expected_rows(tmp_path):
    """1-based frames, percentages, interpolation while `enabled`, hidden after a disabled keyframe,
    visibility spans and events on the timeline, a keypoint sequence (no width/height)."""
    seq = [_kf(1, 9, 18), _kf(5, 13, 22, enabled=False), _kf(8, 49, 48), _kf(10, 49, 48, enabled=False)]
    keypoints = {
        "id": "k1",
        "type": "videokeypoint",
        "to_name": "video",
        "from_name": "kp",
        "value": {"labels": ["ball"], "sequence": [{"frame": 20, "x": 100.0, "y": 0.0, "enabled": False}]},
    }
    result = [
        _box(seq),
        keypoints,
        _timeline("ground", [(3, 3)]),
        _timeline("player_far", [(9, 9)]),
        _timeline("occluded", [(8, 9)]),
        _timeline("out_of_frame", [(11, 12)]),
        _timeline("serve", [(1, 1)]),
    ]
    path = tmp_path / "export.json"
    path.write_text(json.dumps([_ls_task(result)]))
    got = import_labelstudio(path)
    np.testing.assert_array_equal(got.ball.frame, [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 19])
    np.testing.assert_array_equal(got.ball.visibility, [1, 1, 1, 1, 1, 0, 0, 3, 3, 1, 0, 0, 1])
    pct = 100 * got.ball.xy
    np.testing.assert_allclose(pct[:5], [[10, 20], [11, 21], [12, 22], [13, 23], [14, 24]])
    np.testing.assert_allclose(pct[[7, 8, 9, 12]], [[50, 50], [50, 50], [50, 50], [100, 0]])
    assert got.events == HitEvents([2, 8], ["ground", "player_far"])
    assert (got.n_frames, got.fps) == (50, 25.0)  # framesCount / duration
    assert any("'serve'" in w for w in got.warnings)
    task = _ls_task(result)
    task["data"]["fps"] = 29.97
    path.write_text(json.dumps([task]))
    assert import_labelstudio(path).fps == 29.97  # the task's own frame rate comes first


def test_labelstudio_picks_the_task_and_annotation(tmp_path):
    path = tmp_path / "export.json"
    tasks = [_ls_task([_box([_kf(1, 10, 10)])], 1), _ls_task([_box([_kf(2, 20, 20)])], 2)]
    tasks[1]["annotations"].insert(0, {"id": 5, "was_cancelled": True, "result": []})
    path.write_text(json.dumps(tasks))
    with pytest.raises(FormatError, match="--task"):
        import_labelstudio(path)
    got = import_labelstudio(path, task=2)
    np.testing.assert_array_equal(got.ball.frame, [1])  # the cancelled annotation is skipped


# ----------------------------------------------------------------- CVAT's own task and job export layouts
# As CVAT's dataset manager writes them (cvat/apps/dataset_manager/bindings.py, TaskData.meta_for_task
# and JobData._init_meta): a task export keeps <original_size> inside <task>; a job export puts it in
# <meta> after </job> and <dumped>, gives the job's own start/stop frames and its segment of the task,
# and numbers the shapes in video frames. Real tracks list every frame up to the closing outside shape
# (keyframe="0" between keyframes).
CVAT_TRACKS = """  <track id="0" label="ball" source="manual">
    <points frame="{f0}" keyframe="1" outside="0" occluded="0" points="100.00,200.00" z_order="0">
    </points>
    <points frame="{f1}" keyframe="0" outside="0" occluded="0" points="110.00,210.00" z_order="0">
    </points>
    <points frame="{f2}" keyframe="1" outside="0" occluded="1" points="120.00,220.00" z_order="0">
    </points>
    <points frame="{f3}" keyframe="1" outside="1" occluded="0" points="120.00,220.00" z_order="0">
    </points>
  </track>
  <track id="1" label="ground" source="manual">
    <points frame="{f1}" keyframe="1" outside="0" occluded="0" points="110.00,210.00" z_order="0">
    </points>
    <points frame="{f2}" keyframe="1" outside="1" occluded="0" points="110.00,210.00" z_order="0">
    </points>
  </track>
</annotations>
"""
CVAT_LABELS = """      <labels>
        <label>
          <name>ball</name>
          <color>#fa3253</color>
          <type>points</type>
          <attributes>
          </attributes>
        </label>
        <label>
          <name>ground</name>
          <color>#33ddff</color>
          <type>points</type>
          <attributes>
          </attributes>
        </label>
      </labels>
"""
CVAT_TASK_EXPORT = """<?xml version="1.0" encoding="utf-8"?>
<annotations>
  <version>1.1</version>
  <meta>
    <task>
      <id>7</id>
      <name>rally 7</name>
      <size>{size}</size>
      <mode>interpolation</mode>
      <overlap>5</overlap>
      <bugtracker></bugtracker>
      <created>2024-05-02 09:14:03.410870+00:00</created>
      <updated>2024-05-02 10:01:45.102771+00:00</updated>
      <subset>default</subset>
      <start_frame>{start}</start_frame>
      <stop_frame>{stop}</stop_frame>
      <frame_filter>{filter}</frame_filter>
      <segments>
        <segment>
          <id>9</id>
          <start>0</start>
          <stop>{last}</stop>
          <url>http://localhost:8080/api/jobs/12</url>
        </segment>
      </segments>
      <owner>
        <username>anna</username>
        <email>anna@example.com</email>
      </owner>
      <assignee></assignee>
""" + CVAT_LABELS + """      <original_size>
        <width>1280</width>
        <height>720</height>
      </original_size>
      <source>rally_07.mp4</source>
    </task>
    <dumped>2024-05-02 10:02:11.512408+00:00</dumped>
  </meta>
"""
CVAT_JOB_EXPORT = """<?xml version="1.0" encoding="utf-8"?>
<annotations>
  <version>1.1</version>
  <meta>
    <job>
      <id>12</id>
      <size>{size}</size>
      <mode>interpolation</mode>
      <overlap>5</overlap>
      <bugtracker></bugtracker>
      <created>2024-05-02 09:14:03.410870+00:00</created>
      <updated>2024-05-02 10:01:45.102771+00:00</updated>
      <subset>default</subset>
      <start_frame>{start}</start_frame>
      <stop_frame>{stop}</stop_frame>
      <frame_filter>{filter}</frame_filter>
      <segments>
        <segment>
          <id>9</id>
          <start>{seg_start}</start>
          <stop>{last}</stop>
          <url>http://localhost:8080/api/jobs/12</url>
        </segment>
      </segments>
      <owner>
        <username>anna</username>
        <email>anna@example.com</email>
      </owner>
      <assignee></assignee>
""" + CVAT_LABELS + """    </job>
    <dumped>2024-05-02 10:02:11.512408+00:00</dumped>
    <original_size>
      <width>1280</width>
      <height>720</height>
    </original_size>
  </meta>
"""


@pytest.mark.parametrize("layout", ["task", "job"])
def test_cvat_task_and_job_exports_import(rally3d, tmp_path, capsys, layout):
    """A task export and a job export of a one-job task, as CVAT's web app writes them, import alike."""
    template = CVAT_TASK_EXPORT if layout == "task" else CVAT_JOB_EXPORT
    meta = template.format(size=30, start=0, stop=29, filter="", seg_start=0, last=29)
    path = tmp_path / "annotations.xml"
    path.write_text(meta + CVAT_TRACKS.format(f0=2, f1=3, f2=4, f3=5))
    got = import_cvat(path)
    np.testing.assert_array_equal(got.ball.frame, [2, 3, 4])
    np.testing.assert_array_equal(got.ball.visibility, [1, 1, 3])
    np.testing.assert_allclose(got.ball.to_pixels(1280, 720), [[100, 200], [110, 210], [120, 220]])
    assert got.events == HitEvents([3], ["ground"])
    assert (got.width, got.height) == (1280, 720)
    # a job's <size> counts the job's frames, not the clip's: only a task states the clip's length
    assert got.n_frames == (30 if layout == "task" else None)
    assert ("CVAT task 'rally 7'" if layout == "task" else "CVAT job 12") in got.source
    clip = tmp_path / "clip"
    args = ["import", str(path), str(clip), "--sport", "padel", "--fps", "25"]
    assert rally3d(args) == 0, capsys.readouterr()
    np.testing.assert_array_equal(Clip(clip).read_ball().frame, [2, 3, 4])


def test_cvat_job_of_a_longer_task_lands_on_task_frames(tmp_path):
    """Job 2 of a task made with start frame 10 and step 2: the job covers task frames 15-29, i.e. video
    frames 40-68; its shapes carry video frames, and the rows land on the task's (the clip's) frames."""
    meta = CVAT_JOB_EXPORT.format(size=15, start=40, stop=68, filter="step=2", seg_start=15, last=29)
    path = tmp_path / "annotations.xml"
    path.write_text(meta + CVAT_TRACKS.format(f0=40, f1=42, f2=44, f3=46))
    got = import_cvat(path)
    np.testing.assert_array_equal(got.ball.frame, [15, 16, 17])
    assert got.events == HitEvents([16], ["ground"])
    assert any("video frame 10" in w and "step 2" in w for w in got.warnings)
    path.write_text(meta + CVAT_TRACKS.format(f0=40, f1=42, f2=44, f3=72))  # the outside shape past the job
    with pytest.raises(FormatError, match=r"line \d+: frame 72 lies past the job's frames \(task frames 15"):
        import_cvat(path)


def test_cvat_without_original_size_takes_width_and_height(rally3d, tmp_path, capsys):
    """A task made from images states no <original_size>: the fix asks for --width/--height (not for the
    export the user already made), and with them the file imports."""
    meta = CVAT_TASK_EXPORT.format(size=30, start=0, stop=29, filter="", seg_start=0, last=29)
    meta = meta.split("      <original_size>")[0] + "    </task>\n  </meta>\n"
    path = tmp_path / "annotations.xml"
    path.write_text(meta + CVAT_TRACKS.format(f0=2, f1=3, f2=4, f3=5))
    clip = tmp_path / "clip"
    assert rally3d(["import", str(path), str(clip), "--sport", "padel", "--fps", "25"]) == 1
    err = capsys.readouterr().err
    assert "<original_size>" in err and "--width" in err and "--height" in err
    assert "export with" not in err
    args = ["import", str(path), str(clip), "--sport", "padel", "--fps", "25"]
    args += ["--width", "1280", "--height", "720"]
    assert rally3d(args) == 0, capsys.readouterr().err
    np.testing.assert_allclose(Clip(clip).read_ball().to_pixels(1280, 720)[0], [100, 200])
    # into an existing clip, its clip.yaml gives the size
    assert rally3d(["import", str(path), str(clip), "--overwrite"]) == 0, capsys.readouterr().err
    np.testing.assert_allclose(Clip(clip).read_ball().to_pixels(1280, 720)[0], [100, 200])


# ------------------------------------------------------------------------------- Label Studio's time
def test_labelstudio_export_writes_time_as_frame_over_fps(tmp_path):
    """Label Studio (its editor, converter and ML backend) writes a keyframe's time as frame / fps with
    the 1-based frame; so does the export."""
    from inference.interchange.labelstudio import export_labelstudio

    clip = _awkward_clip(tmp_path / "c")
    out = export_labelstudio(
        tmp_path / "a.json", clip.read_ball(), clip.read_events(), width=1920, height=1080,
        n_frames=60, fps=25.0,
    )
    result = json.loads(out.read_text())[0]["annotations"][0]["result"]
    items = [k for r in result if r["type"] == "videorectangle" for k in r["value"]["sequence"]]
    assert items and all(k["time"] == pytest.approx(k["frame"] / 25.0, abs=1e-6) for k in items)


def _ls_own_task() -> dict:
    """A task as Label Studio's editor saves it (its own test fixture's layout): frameRate 24 in the
    config, time = frame / 24, framesCount and duration from the browser, no fps in the data."""
    seq = [
        {"frame": 1, "enabled": True, "rotation": 0, "x": 9.0, "y": 18.0, "width": 2.0, "height": 4.0,
         "time": 1 / 24},
        {"frame": 5, "enabled": False, "rotation": 0, "x": 13.0, "y": 22.0, "width": 2.0, "height": 4.0,
         "time": 5 / 24},
        {"frame": 9, "enabled": False, "rotation": 0, "x": 49.0, "y": 48.0, "width": 2.0, "height": 4.0,
         "time": 9 / 24},
    ]
    region = {"id": "RRxnu061g3", "type": "videorectangle", "from_name": "box", "to_name": "video",
              "origin": "manual",
              "value": {"framesCount": 131, "duration": 5.425, "sequence": seq, "labels": ["ball"]}}
    return {"id": 3, "data": {"video": "/data/upload/1/rally.mp4"},
            "annotations": [{"id": 9, "was_cancelled": False, "result": [region]}]}


def test_labelstudio_own_layout_round_trips(tmp_path):
    """Label Studio's file -> clip rows -> rally3d's file: each keyframe comes back on the same frame at
    the same time, and the rows read back the same."""
    from inference.interchange.labelstudio import export_labelstudio

    path = tmp_path / "ls.json"
    task = _ls_own_task()
    path.write_text(json.dumps([task]))
    got = import_labelstudio(path)
    assert not got.warnings
    np.testing.assert_array_equal(got.ball.frame, np.arange(9))
    np.testing.assert_array_equal(got.ball.visibility, [1, 1, 1, 1, 1, 0, 0, 0, 1])  # hidden after frame 5
    out = export_labelstudio(tmp_path / "back.json", got.ball, got.events, width=1280, height=720,
                             n_frames=131, fps=24.0)
    region = json.loads(out.read_text())[0]["annotations"][0]["result"][0]
    back = {k["frame"]: k for k in region["value"]["sequence"]}
    for key in task["annotations"][0]["result"][0]["value"]["sequence"]:
        assert back[key["frame"]]["time"] == pytest.approx(key["time"], abs=1e-6)
    again = import_labelstudio(out)
    _same_ball(got.ball, again.ball)


def test_labelstudio_frame_rate_mismatch_is_reported(tmp_path):
    """Keyframe times say Label Studio counted frames at 24 fps (time = frame / frameRate) while the task
    states 30: its frame numbers drift from the video's, and the import says which setting to fix."""
    task = _ls_own_task()
    task["data"]["fps"] = 30
    path = tmp_path / "ls.json"
    path.write_text(json.dumps([task]))
    warnings = import_labelstudio(path).warnings
    assert any("24 fps" in w and "frameRate" in w and "result[0]" in w for w in warnings), warnings


# ------------------------------------------------------------------------------------------ bad input
BILLION_LAUGHS = """<?xml version="1.0"?>
<!DOCTYPE lolz [<!ENTITY lol "lol"><!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">]>
<annotations><version>&lol2;</version></annotations>
"""
EXTERNAL = """<?xml version="1.0"?>
<!DOCTYPE annotations SYSTEM "http://example.invalid/evil.dtd">
<annotations/>
"""
POINT = (
    '<track id="0" label="ball"><points frame="{f}" keyframe="1" outside="0" occluded="0" points="{p}"/>'
    "</track>"
)

BAD_CVAT = [
    ("entities", BILLION_LAUGHS, ["DOCTYPE or ENTITY", "line 2"]),
    ("external dtd", EXTERNAL, ["refused for safety"]),
    (
        "truncated",
        CVAT_META.format(size=5, stop=4) + '  <track id="0" label="ball">\n    <points frame="1"',
        ["not well-formed XML", "fix:"],
    ),
    (
        "two points",
        CVAT_META.format(size=5, stop=4) + POINT.format(f=1, p="1,1;2,2") + "</annotations>",
        ["line 12", "exactly one"],
    ),
    (
        "frame text",
        CVAT_META.format(size=5, stop=4) + POINT.format(f="one", p="1,1") + "</annotations>",
        ["line 12", "frame='one'", "whole number"],
    ),
    (
        "off image",
        CVAT_META.format(size=5, stop=4) + POINT.format(f=1, p="1300,10") + "</annotations>",
        ["line 12", "outside the 1280x720 image"],
    ),
    (
        "past the end",
        CVAT_META.format(size=5, stop=4) + POINT.format(f=7, p="10,10") + "</annotations>",
        ["frame 7", "5 frames"],
    ),
    (
        "two events",
        CVAT_META.format(size=5, stop=4) + '<tag frame="2" label="ground"/><tag frame="2" label="net"/>'
        "</annotations>",
        ["frame 2 has two events", "next frame"],
    ),
    (
        "images",
        CVAT_META.format(size=5, stop=4) + '<image id="0" name="a.jpg"/></annotations>',
        ["CVAT for images", "CVAT for video 1.1"],
    ),
    ("no meta", "<annotations><version>1.1</version></annotations>", ["no <meta>"]),
    (
        "step 0",
        CVAT_META.format(size=5, stop=4).replace("<frame_filter><", "<frame_filter>step=0<")
        + POINT.format(f=1, p="1,1")
        + "</annotations>",
        ["line 7", "step=0", "step=1"],
    ),
    (
        "size absurd",
        CVAT_META.format(size=2_000_000_000, stop=4) + POINT.format(f=1, p="1,1") + "</annotations>",
        ["line 6", "<size> 2000000000", "3456000"],
    ),
    (
        "frame absurd",
        CVAT_META.format(size=5, stop=4) + POINT.format(f=10**23, p="1,1") + "</annotations>",
        ["line 12", "frame 100000000000000000000000", "5 frames"],
    ),
    (
        "image absurd",
        CVAT_META.format(size=5, stop=4).replace("<width>1280</width>", "<width>1000000000000</width>")
        + POINT.format(f=1, p="1,1")
        + "</annotations>",
        ["line 9", "1000000000000", "--width"],
    ),
]


@pytest.mark.parametrize("name,text,words", BAD_CVAT, ids=[b[0] for b in BAD_CVAT])
def test_bad_cvat_files_get_clear_errors(rally3d, tmp_path, capsys, name, text, words):
    path = tmp_path / "annotations.xml"
    path.write_text(text)
    assert rally3d(["import", str(path), str(tmp_path / "clip"), "--sport", "padel", "--fps", "25"]) == 1
    err = capsys.readouterr().err
    assert str(path) in err and "fix:" in err and "Traceback" not in err
    for word in words:
        assert word in err
    assert not (tmp_path / "clip").exists()  # nothing written


BAD_LS = [
    ("not json", '[{"id": 1,\n "data": }]', ["not valid JSON", "line 2"]),
    ("not tasks", '{"foo": 1}', ["item 0 is not a Label Studio task"]),
    (
        "no annotation",
        '[{"id": 4, "data": {"video": "v.mp4"}, "annotations": []}]',
        ["task 4 has no annotation"],
    ),
    ("csv export", '"a,b"', ["not a list of tasks", "JSON-MIN"]),
    ("frame 0", [_ls_task([_box([_kf(0, 10, 10)])])], ["sequence[0]", "counts video frames from 1"]),
    ("x text", [_ls_task([_box([{"frame": 1, "x": "ten", "y": 1}])])], ["sequence[0]", "'x' is 'ten'"]),
    ("off frame", [_ls_task([_box([_kf(1, 150, 10)])])], ["outside the frame", "percentages"]),
    ("two tasks", [_ls_task([], 1), _ls_task([], 2)], ["2 tasks", "--task ID"]),
    (
        "out but boxed",
        [_ls_task([_box([_kf(1, 10, 10)]), _timeline("out_of_frame", [(1, 1)])])],
        ["out_of_frame but has a ball box"],
    ),
    ("occluded no box", [_ls_task([_timeline("occluded", [(4, 6)])])], ["frame 4", "has no ball box"]),
    ("backwards", [_ls_task([_timeline("ground", [(6, 4)])])], ["ranges[0]", "swap start and end"]),
    ("event box", [_ls_task([_box([_kf(1, 10, 10)], labels=("ground",))])], ["TimelineLabels"]),
    (
        "predictions not a list",
        [{"id": 4, "data": {"video": "v.mp4"}, "annotations": [], "predictions": 1.5}],
        ["task 4", "'predictions' is 1.5", "list"],
    ),
    (
        "annotations not a list",
        [{"id": 4, "data": {}, "annotations": 1.5}],
        ["task 4", "'annotations' is 1.5"],
    ),
    (
        "past framesCount",
        [_ls_task([_box([_kf(51, 10, 10)])])],
        ["sequence[0]", "frame 51", "framesCount 50"],
    ),
    (
        "framesCount absurd",
        [_ls_task([{**_box([_kf(1, 10, 10)]), "value": {**_box([])["value"], "framesCount": 2_000_000_000,
                                                         "sequence": [_kf(1, 10, 10)]}}])],
        ["result[0]", "framesCount 2000000000", "3456000"],
    ),
    ("data not a mapping", [_ls_task([], 1), {**_ls_task([], 2), "data": [1]}], ["2 tasks", "--task ID"]),
]


@pytest.mark.parametrize("name,content,words", BAD_LS, ids=[b[0] for b in BAD_LS])
def test_bad_labelstudio_files_get_clear_errors(rally3d, tmp_path, capsys, name, content, words):
    path = tmp_path / "export.json"
    path.write_text(content if isinstance(content, str) else json.dumps(content))
    assert (
        rally3d(
            [
                "import",
                str(path),
                str(tmp_path / "clip"),
                "--sport",
                "padel",
                "--width",
                "1280",
                "--height",
                "720",
            ]
        )
        == 1
    )
    err = capsys.readouterr().err
    assert str(path) in err and "fix:" in err and "Traceback" not in err
    for word in words:
        assert word in err
    assert not (tmp_path / "clip").exists()


def test_xml_guard_without_defusedxml(monkeypatch, tmp_path):
    """Where defusedxml is not installed the standard parser runs, behind the DOCTYPE/ENTITY check."""
    monkeypatch.setitem(sys.modules, "defusedxml.sax", None)  # import fails
    bad = tmp_path / "bad.xml"
    bad.write_text(BILLION_LAUGHS.replace("DOCTYPE", "doctype"))
    with pytest.raises(FormatError, match="DOCTYPE or ENTITY"):
        parse_xml(bad)
    good = _cvat(tmp_path, POINT.format(f=1, p="640,360") + "\n")
    np.testing.assert_allclose(import_cvat(good).ball.xy, [[0.5, 0.5]])


def test_new_clip_needs_sport_and_fps(rally3d, tmp_path, capsys):
    path = _cvat(tmp_path, POINT.format(f=1, p="640,360") + "\n")
    assert rally3d(["import", str(path), str(tmp_path / "clip")]) == 1
    err = capsys.readouterr().err
    assert "--sport" in err and "--fps" in err
    assert (
        rally3d(
            [
                "import",
                str(path),
                str(tmp_path / "clip"),
                "--sport",
                "tennis",
                "--fps",
                "50",
                "--video",
                "../match.mp4",
            ]
        )
        == 0
    )
    info = Clip(tmp_path / "clip").info
    assert (info.sport, info.fps, info.width, info.height, info.video, info.n_frames) == (
        "tennis",
        50.0,
        1280,
        720,
        "../match.mp4",
        30,
    )
    assert "CVAT task 'rally 7'" in info.source


def test_import_refuses_another_aspect_ratio(rally3d, tmp_path, capsys):
    clip = _awkward_clip(tmp_path / "c")  # 1920x1080
    path = _cvat(tmp_path, POINT.format(f=1, p="640,360") + "\n")
    text = path.read_text().replace("<height>720</height>", "<height>1024</height>")
    path.write_text(text)
    assert rally3d(["import", str(path), str(clip.root), "--overwrite"]) == 1
    assert "aspect ratio" in capsys.readouterr().err


def test_import_checks_frames_against_the_video(rally3d, tmp_path, capsys):
    """A clip.yaml without n_frames: the frames folder's length bounds the rows."""
    from inference.clipio import write_frames_folder

    root = tmp_path / "clip"
    Clip.create(root, ClipInfo(sport="padel", fps=30.0, width=64, height=36, video="frames/"))
    write_frames_folder(root / "frames", [np.zeros((36, 64, 3), np.uint8)] * 5)
    path = _cvat(tmp_path, POINT.format(f=7, p="640,360") + "\n", size=40)
    assert rally3d(["import", str(path), str(root)]) == 1
    assert "line 12: frame 7 lies past the clip's 5 frames" in capsys.readouterr().err
    path = _cvat(tmp_path, POINT.format(f=4, p="640,360") + "\n", size=40)
    assert rally3d(["import", str(path), str(root)]) == 0
    assert "the file states 40 frames, the clip has 5" in capsys.readouterr().out
    np.testing.assert_array_equal(Clip(root).read_ball().frame, [4])


def test_frames_are_bounded_by_the_existing_clip(rally3d, tmp_path, capsys):
    """A file that states no length, into a 60-frame clip: frame 100000 is refused at its place, before
    the frames between the keyframes are built."""
    clip = _awkward_clip(tmp_path / "c")
    region = {"type": "videorectangle", "value": {"labels": ["ball"], "sequence": [_kf(1, 10, 10),
                                                                                    _kf(100_000, 20, 20)]}}
    path = tmp_path / "export.json"
    path.write_text(json.dumps([_ls_task([region])]))
    assert rally3d(["import", str(path), str(clip.root), "--overwrite"]) == 1
    err = capsys.readouterr().err
    assert "result[0], sequence[1]: frame 100000 lies past the clip's 60 frames" in err and "fix:" in err


def test_export_never_overwrites_without_backup(rally3d, tmp_path, capsys):
    clip = _awkward_clip(tmp_path / "c")
    out = tmp_path / "out.json"
    out.write_text("my own file")
    assert rally3d(["export", str(clip.root), "--out", str(out)]) == 1
    assert "--overwrite" in capsys.readouterr().err and out.read_text() == "my own file"
    assert rally3d(["export", str(clip.root), "--out", str(out), "--overwrite"]) == 0
    assert [p.read_text() for p in tmp_path.glob("out.json.*.bak")] == ["my own file"]


def test_dry_run_writes_nothing(rally3d, tmp_path, capsys):
    path = _cvat(tmp_path, POINT.format(f=1, p="640,360") + "\n")
    assert rally3d(["import", str(path), str(tmp_path / "clip"), "--dry-run"]) == 0
    assert "1 ball rows (1 visible)" in capsys.readouterr().out
    assert not (tmp_path / "clip").exists()


@pytest.mark.parametrize("cmd", ["import", "export"])
def test_help_reads_well(rally3d, cmd, capsys):
    with pytest.raises(SystemExit) as e:
        rally3d([cmd, "--help"])
    assert e.value.code == 0
    out = capsys.readouterr().out
    for word in ("CVAT", "Label Studio", "docs/interchange.md", "examples:"):
        assert word in out


# ---------------------------------------------------------------------- bounds before any allocation
DRIVER = """
import sys
from importlib.metadata import EntryPoint
import inference.cli as cli
eps = [EntryPoint(n, f"inference.interchange.cli:register_{n}", cli.GROUP) for n in ("import", "export")]
cli.entry_points = lambda group: eps if group == cli.GROUP else []
sys.exit(cli.main(sys.argv[1:]))
"""
ADDRESS_SPACE = 1 << 30
"""The capped `rally3d import` may map 1 GiB (it needs ~150 MB); the unbounded code grew past 3.5 GB."""


def _absurd_files(tmp_path: Path) -> dict[str, Path]:
    """Small files that address billions of frames: one shape at frame 1e23, a 2e9-frame task, a keyframe
    and a timeline range at frame 2e9 (with and without framesCount)."""
    key = '<points frame="{f}" keyframe="1" outside="0" occluded="0" points="1,1"/>'
    track = '<track id="0" label="ball">' + key.format(f=0) + key.format(f="{f}") + "</track></annotations>"
    no_size = CVAT_META.replace("<size>{size}</size>", "")
    files = {
        "cvat frame 1e23": no_size.format(stop=4) + track.format(f=10**23),
        "cvat frame 1e23 in 30": CVAT_META.format(size=30, stop=29) + track.format(f=10**23),
        "cvat size 2e9": CVAT_META.format(size=2 * 10**9, stop=2 * 10**9 - 1) + track.format(f=2 * 10**9 - 1),
        "ls frame 2e9": json.dumps([_ls_task([_box([_kf(1, 10, 10), _kf(2 * 10**9, 20, 20)])])]),
        "ls frame 2e9 no count": json.dumps(
            [_ls_task([{"type": "videorectangle", "value": {"labels": ["ball"], "sequence": [
                _kf(1, 10, 10), _kf(2 * 10**9, 20, 20)]}}])]),
        "ls range 2e9": json.dumps([_ls_task([_timeline("out_of_frame", [(1, 2 * 10**9)])])]),
    }
    paths = {}
    for name, text in files.items():
        paths[name] = tmp_path / (name.replace(" ", "_") + (".xml" if name.startswith("cvat") else ".json"))
        paths[name].write_text(text)
    return paths


@pytest.mark.parametrize(
    "name",
    ["cvat frame 1e23", "cvat frame 1e23 in 30", "cvat size 2e9", "ls frame 2e9", "ls frame 2e9 no count",
     "ls range 2e9"],
)
def test_absurd_frame_numbers_are_refused_before_allocating(tmp_path, name):
    """`rally3d import` of a file addressing billions of frames: a clear error within a 1 GiB address
    space (the unbounded code filled it and died with a MemoryError traceback)."""
    resource = pytest.importorskip("resource")
    path = _absurd_files(tmp_path)[name]

    def cap() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))

    args = ["import", str(path), str(tmp_path / "clip"), "--sport", "padel", "--fps", "25",
            "--width", "1280", "--height", "720"]
    done = subprocess.run([sys.executable, "-c", DRIVER, *args], cwd=REPO, capture_output=True, text=True,
                          preexec_fn=cap, timeout=600)
    assert done.returncode == 1, done.stderr[-2000:]
    assert "Traceback" not in done.stderr and "MemoryError" not in done.stderr, done.stderr[-2000:]
    assert str(path) in done.stderr and "fix:" in done.stderr and "frame" in done.stderr
    assert not (tmp_path / "clip").exists()
