"""The Clip folder object: paths, lazy clip.yaml, typed reads/writes, frames and camera delegation."""

import sys
import types

import numpy as np
import pytest

from inference.clipio import (
    Ball3D,
    BallTrack,
    Clip,
    ClipInfo,
    CourtPoints,
    FormatError,
    HitEvents,
    InactiveBalls,
    write_frames_folder,
)

INFO = ClipInfo("padel", 30.0, 64, 48, "frames/", n_frames=10)


@pytest.fixture
def clip(tmp_path):
    return Clip.create(tmp_path / "rally", INFO)


def test_create_and_lazy_info(tmp_path, clip):
    assert clip.clip_yaml_path.is_file()
    assert Clip(clip.root).info == INFO
    with pytest.raises(FileExistsError):
        Clip.create(clip.root, INFO)
    Clip.create(clip.root, INFO, exist_ok=True)
    lazy = Clip(tmp_path / "nowhere")  # constructing reads nothing
    with pytest.raises(FormatError, match=r"clip.yaml: file not found"):
        lazy.info


def test_paths(clip):
    assert clip.ball_path.name == "ball.csv"
    assert clip.inactive_balls_path.name == "inactive_balls.csv"
    assert clip.events_path.name == "events.csv"
    assert clip.court_points_path.name == "court_points.csv"
    assert clip.camera_path.name == "camera.yaml"
    assert clip.ball_3d_path.name == "ball_3d.csv"
    assert clip.video_path == clip.root / "frames"
    assert clip.gt_dir == clip.root / "gt"


TABLES = [
    ("ball", BallTrack(frame=[0, 9], visibility=[1, 0], xy=[[0.5, 0.5], [np.nan, np.nan]])),
    ("inactive_balls", InactiveBalls(frame=[2], ball_no=[0], xy=[[0.2, 0.8]])),
    ("events", HitEvents(frame=[4], event=["wall_left"])),
    ("court_points", CourtPoints(["near_left"], [[0.1, 0.9]])),
    ("ball_3d", Ball3D(frame=[1], xyz=[[5.0, 3.0, 1.2]], segment=[0], kind=["fitted"], sigma=[0.05])),
]


@pytest.mark.parametrize(("name", "obj"), TABLES, ids=[t[0] for t in TABLES])
def test_table_round_trip(clip, name, obj):
    path = getattr(clip, f"write_{name}")(obj)
    assert path == getattr(clip, f"{name}_path")
    assert getattr(clip, f"read_{name}")() == obj


@pytest.mark.parametrize(("name", "obj"), TABLES, ids=[t[0] for t in TABLES])
def test_missing_table(clip, name, obj):
    with pytest.raises(FormatError, match="file not found"):
        getattr(clip, f"read_{name}")()
    assert len(getattr(clip, f"read_{name}")(missing_ok=True)) == 0


@pytest.mark.parametrize("name", ["events", "ball_3d"])
def test_ground_truth_tables(clip, name):
    obj = dict(TABLES)[name]
    path = getattr(clip, f"write_{name}")(obj, gt=True)
    assert path.parent == clip.gt_dir
    assert getattr(clip, f"read_{name}")(gt=True) == obj
    assert not getattr(clip, f"{name}_path").exists()


def test_frames_beyond_clip_length_rejected(clip):
    clip.ball_path.write_text("frame,visibility,x,y\n0,0,,\n10,1,0.5,0.5\n")
    with pytest.raises(FormatError, match=r"ball.csv, line 3: frame 10 is beyond the video \(10 frames\)"):
        clip.read_ball()
    assert len(clip.read_ball(n_frames=11)) == 2
    with pytest.raises(FormatError, match=r"ball.csv, line 3: frame 10 is beyond the video \(5 frames\)"):
        clip.read_ball(n_frames=5)


def test_court_points_checked_against_known_names(clip):
    clip.court_points_path.write_text("name,x,y\nnear_left,0.1,0.9\nfar_lft,0.2,0.3\n")
    assert len(clip.read_court_points()) == 2
    with pytest.raises(
        FormatError, match=r"line 3: unknown court point 'far_lft' \(did you mean 'far_left'\?\)"
    ):
        clip.read_court_points(known_names=["near_left", "far_left"])


def test_frames_and_n_frames(tmp_path):
    clip = Clip.create(tmp_path, ClipInfo("tennis", 25.0, 32, 24, "frames/"))
    write_frames_folder(clip.video_path, (np.full((24, 32, 3), i * 20, np.uint8) for i in range(7)))
    assert clip.n_frames == 7
    with clip.frames() as src:
        assert len(src) == 7 and src.fps == 25.0
        assert abs(int(src[6].mean()) - 120) <= 2
    assert Clip.create(tmp_path / "b", INFO).n_frames == 10  # from clip.yaml, no frames needed


def test_court_path(clip, tmp_path):
    assert clip.court_path(tmp_path / "courts") == tmp_path / "courts" / "padel.yaml"
    assert clip.court_path().parts[-3:] == ("conf", "court", "padel.yaml")
    custom = Clip.create(tmp_path / "c", ClipInfo("padel", 30, 64, 48, "video.mp4", court="my_court.yaml"))
    assert custom.court_path() == custom.root / "my_court.yaml"


def test_camera_is_delegated_to_inference_camera(clip, monkeypatch):
    class FakeCamera:
        def __init__(self, text):
            self.text = text

        @classmethod
        def load(cls, path):
            return cls(path.read_text())

        def save(self, path):
            path.write_text(self.text)

    module = types.ModuleType("inference.camera")
    module.Camera = FakeCamera
    monkeypatch.setitem(sys.modules, "inference.camera", module)
    with pytest.raises(FormatError, match=r"camera.yaml: file not found"):
        clip.read_camera()
    assert clip.write_camera(FakeCamera("P: []\n")) == clip.camera_path
    assert clip.read_camera().text == "P: []\n"
    clip.write_camera(FakeCamera("gt\n"), gt=True)
    assert clip.read_camera(gt=True).text == "gt\n"


def test_csv_only_clip_counts_frames_from_its_tables(tmp_path):
    """No video and no n_frames: the frame count comes from ball.csv / events.csv / players.csv."""
    from inference.clipio import Clip

    (tmp_path / "clip.yaml").write_text("sport: tennis\nfps: 25\nwidth: 1280\nheight: 720\nvideo: gone.mp4\n")
    (tmp_path / "ball.csv").write_text("frame,visibility,x,y\n0,1,0.5,0.5\n57,1,0.4,0.4\n")
    (tmp_path / "events.csv").write_text("frame,event\n12,player_near\n80,ground\n")
    clip = Clip(tmp_path)
    with pytest.warns(UserWarning, match="81 frames taken from the clip's tables"):
        assert clip.n_frames == 81
    bare = tmp_path / "bare"
    bare.mkdir()
    (bare / "clip.yaml").write_text("sport: tennis\nfps: 25\nwidth: 1280\nheight: 720\nvideo: gone.mp4\n")
    with pytest.raises(FormatError, match="no table names a frame"):
        Clip(bare).n_frames
