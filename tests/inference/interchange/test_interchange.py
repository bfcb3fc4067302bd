"""CVAT for video 1.1 and Label Studio video JSON <-> clip folders: round trips, hand-written files in the
documented layouts, clear errors on bad input, safe XML, and the `rally3d import/export` commands."""

from __future__ import annotations

import json
import shutil
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
    assert rally3d(["import", str(out), str(new), "--overwrite"]) == 0
    assert sorted(p.name.split(".csv")[0] for p in (new / ".rally3d" / "backup").iterdir()) == [
        "ball",
        "events",
    ]
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
    assert "ball on frame 7, but the clip has 5 frames" in capsys.readouterr().err
    path = _cvat(tmp_path, POINT.format(f=4, p="640,360") + "\n", size=40)
    assert rally3d(["import", str(path), str(root)]) == 0
    assert "the file states 40 frames, the clip has 5" in capsys.readouterr().out
    np.testing.assert_array_equal(Clip(root).read_ball().frame, [4])


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
