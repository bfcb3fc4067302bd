"""Round trips and rejected inputs of the clip CSV files (inference.clipio.csvfiles)."""


import numpy as np
import pytest

import inference.clipio.atomic as atomic
from inference.clipio import (
    Ball3D,
    BallTrack,
    CourtPoints,
    FormatError,
    HitEvents,
    InactiveBalls,
    read_ball_3d_csv,
    read_ball_csv,
    read_court_points_csv,
    read_events_csv,
    read_inactive_balls_csv,
    write_ball_3d_csv,
    write_ball_csv,
    write_court_points_csv,
    write_events_csv,
    write_inactive_balls_csv,
)

NAN = np.nan
rng = np.random.default_rng(0)

SAMPLES = {
    "ball.csv": (
        read_ball_csv,
        write_ball_csv,
        BallTrack(
            frame=[0, 1, 4, 7],
            visibility=[1, 0, 2, 3],
            xy=[[0.1234567, 0.5], [NAN, NAN], [0.0, 1.0], [0.999, 0.001]],
        ),
    ),
    "inactive_balls.csv": (
        read_inactive_balls_csv,
        write_inactive_balls_csv,
        InactiveBalls(frame=[0, 0, 5], ball_no=[0, 2, 1], xy=[[0.1, 0.9], [0.25, 0.75], [0.5, 0.5]]),
    ),
    "events.csv": (
        read_events_csv,
        write_events_csv,
        HitEvents(frame=[3, 10, 11, 40], event=["player_near", "ground", "wall_far", "net"]),
    ),
    "court_points.csv": (
        read_court_points_csv,
        write_court_points_csv,
        CourtPoints(["near_left", "near_right", "net_left_top"], [[0.1, 0.9], [0.9, 0.9], [0.05, 0.4]]),
    ),
    "ball_3d.csv": (
        read_ball_3d_csv,
        write_ball_3d_csv,
        Ball3D(
            frame=[0, 0, 1, 2],
            xyz=[[1.5, 2.25, 0.1], [1.5, 2.2, 0.1], [1.6, 2.4, 0.3], [1.7, 2.6, 0.0]],
            segment=[0, -1, 0, 1],
            kind=["fitted", "gt", "fitted", "contact"],
            sigma=[0.01, NAN, 0.02, 0.0],
        ),
    ),
}
EMPTY = {
    "ball.csv": BallTrack.empty(),
    "inactive_balls.csv": InactiveBalls.empty(),
    "events.csv": HitEvents.empty(),
    "court_points.csv": CourtPoints([], []),
    "ball_3d.csv": Ball3D.empty(),
}


@pytest.mark.parametrize("name", SAMPLES)
@pytest.mark.parametrize("empty", [False, True], ids=["rows", "empty"])
def test_round_trip(tmp_path, name, empty):
    read, write, sample = SAMPLES[name]
    obj = EMPTY[name] if empty else sample
    path = write(tmp_path / name, obj)
    assert path == tmp_path / name
    assert read(path) == obj
    first = path.read_bytes()
    write(path, read(path))
    assert path.read_bytes() == first, "writing is deterministic"


def test_ball_csv_text(tmp_path):
    _, write, sample = SAMPLES["ball.csv"]
    text = write(tmp_path / "ball.csv", sample).read_text()
    assert text.splitlines() == [
        "frame,visibility,x,y",
        "0,1,0.1234567,0.5000000",
        "1,0,,",
        "4,2,0.0000000,1.0000000",
        "7,3,0.9990000,0.0010000",
    ]


def test_ball_3d_text_has_metres_with_5_decimals(tmp_path):
    text = write_ball_3d_csv(tmp_path / "b.csv", SAMPLES["ball_3d.csv"][2]).read_text().splitlines()
    assert text[0] == "frame,x_m,y_m,z_m,segment,kind,sigma_m"
    assert text[1] == "0,1.50000,2.25000,0.10000,0,fitted,0.01000"
    assert text[2] == "0,1.50000,2.20000,0.10000,-1,gt,"


def test_round_trip_random_track(tmp_path):
    n = 500
    frame = np.sort(rng.choice(5000, n, replace=False))
    vis = rng.integers(0, 4, n)
    xy = np.where((vis > 0)[:, None], rng.random((n, 2)), NAN)
    t = BallTrack(frame, vis, xy)
    back = read_ball_csv(write_ball_csv(tmp_path / "ball.csv", t))
    assert np.array_equal(back.frame, t.frame) and np.array_equal(back.visibility, t.visibility)
    np.testing.assert_allclose(back.xy, t.xy, atol=5e-8)


def test_readers_sort_rows(tmp_path):
    (tmp_path / "ball.csv").write_text("frame,visibility,x,y\n5,1,0.5,0.5\n2,0,,\n3,1,0.1,0.2\n")
    assert read_ball_csv(tmp_path / "ball.csv").frame.tolist() == [2, 3, 5]
    (tmp_path / "inactive_balls.csv").write_text("frame,ball_no,x,y\n5,1,0.5,0.5\n5,0,0.1,0.1\n2,3,0.2,0.2\n")
    balls = read_inactive_balls_csv(tmp_path / "inactive_balls.csv")
    assert list(zip(balls.frame.tolist(), balls.ball_no.tolist())) == [(2, 3), (5, 0), (5, 1)]


def test_ball_csv_tolerates_zero_coords_when_invisible_and_tiny_overshoot(tmp_path):
    path = tmp_path / "ball.csv"
    path.write_text("frame, visibility ,x,y\r\n0,0,0,0\r\n\r\n1,1,1.0000005,-0.0000003\r\n2,0,,0\r\n")
    t = read_ball_csv(path)
    assert t.frame.tolist() == [0, 1, 2]
    assert np.isnan(t.xy[[0, 2]]).all()
    assert t.xy[1].tolist() == [1.0, 0.0]


def test_ball_3d_keeps_extra_columns(tmp_path):
    path = tmp_path / "ball_3d.csv"
    path.write_text(
        "frame,x_m,y_m,z_m,segment,kind,score,note\n1,1,2,3,0,fitted,0.93,a b\n0,1,2,3,0,gt,1e-3,\n"
    )
    ball = read_ball_3d_csv(path)
    assert list(ball.extra) == ["score", "note"]
    assert ball.extra["score"].tolist() == ["1e-3", "0.93"]  # sorted by frame, text kept as written
    assert np.isnan(ball.sigma).all()
    write_ball_3d_csv(path, ball)
    assert path.read_text().splitlines() == [
        "frame,x_m,y_m,z_m,segment,kind,sigma_m,score,note",
        "0,1.00000,2.00000,3.00000,0,gt,,1e-3,",
        "1,1.00000,2.00000,3.00000,0,fitted,,0.93,a b",
    ]
    assert read_ball_3d_csv(path) == ball


B = "frame,visibility,x,y\n"
MALFORMED = [
    # (file name, content, reader kwargs, line, words in the message)
    ("ball.csv", "", {}, 1, ["empty file", "frame,visibility,x,y"]),
    (
        "ball.csv",
        "frame,visiblity,x,y\n0,1,0.5,0.5\n",
        {},
        1,
        ["missing column", "'visiblity'", "'visibility'"],
    ),
    (
        "ball.csv",
        "frame,x,y\n0,0.5,0.5\n",
        {},
        1,
        ["missing column", "frame,visibility,x,y", "found frame,x,y"],
    ),
    ("ball.csv", B + "0,1,0.5,0.5\n1,1,abc,0.5\n", {}, 3, ["not a number", "'abc'"]),
    ("ball.csv", B + "0,1,0.5,0.5\n1,1,nan,0.5\n", {}, 3, ["'nan'"]),
    ("ball.csv", B + "0,1,inf,0.5\n", {}, 2, ["'inf'"]),
    ("ball.csv", B + "0,1,0.5,0.5\n\n1,1,1.2,0.5\n", {}, 4, ["outside [0, 1]", "x"]),
    ("ball.csv", B + "0,1,0.5,-0.1\n", {}, 2, ["outside [0, 1]", "y"]),
    ("ball.csv", B + "0,4,0.5,0.5\n", {}, 2, ["visibility 4", "0..3"]),
    ("ball.csv", B + "0,1,0.5,0.5\n1,2,,\n", {}, 3, ["x or y is empty", "set visibility 0"]),
    ("ball.csv", B + "0,0,0.4,0.5\n", {}, 2, ["visibility 0 but"]),
    ("ball.csv", B + "0,1,0.5,0.5\n1,1,0.5,0.5\n0,1,0.5,0.5\n", {}, 4, ["duplicate frame 0"]),
    ("ball.csv", B + "0,1,0.5,0.5\n-3,1,0.5,0.5\n", {}, 3, ["negative frame -3"]),
    ("ball.csv", B + "0,1,0.5,0.5\n1.5,1,0.5,0.5\n", {}, 3, ["not an integer"]),
    ("ball.csv", B + ",1,0.5,0.5\n", {}, 2, ["frame is empty"]),
    ("ball.csv", B + "0,1,0.5,0.5\n99,1,0.5,0.5\n", {"n_frames": 99}, 3, ["beyond the video", "0..98"]),
    ("ball.csv", B + "0,1,0.5\n", {}, 2, ["3 fields", "header has 4"]),
    (
        "inactive_balls.csv",
        "frame,ball_no,x,y\n0,0,0.1,0.1\n0,0,0.2,0.2\n",
        {},
        3,
        ["duplicate (frame, ball_no)"],
    ),
    ("inactive_balls.csv", "frame,ball_no,x,y\n0,-1,0.1,0.1\n", {}, 2, ["negative ball_no"]),
    ("inactive_balls.csv", "frame,ball_no,x,y\n0,0,,0.1\n", {}, 2, ["x is empty"]),
    (
        "events.csv",
        "frame,event\n3,ground\n7,bounce\n",
        {},
        3,
        ["unknown event 'bounce'", "wall_near", "player_far"],
    ),
    ("events.csv", "frame,event\n3,ground\n7,player_nera\n", {}, 3, ["did you mean 'player_near'"]),
    ("events.csv", "frame,event\n3,ground\n50,net\n", {"n_frames": 50}, 3, ["beyond the video"]),
    (
        "court_points.csv",
        "name,x,y\nnear_left,0.1,0.9\nnear_rigth,0.9,0.9\n",
        {"known_names": ["near_left", "near_right", "far_left"]},
        3,
        ["unknown court point 'near_rigth'", "did you mean 'near_right'", "near_left, near_right, far_left"],
    ),
    ("court_points.csv", "name,x,y\nnear_left,0.1,0.9\nnear_left,0.2,0.9\n", {}, 3, ["duplicate point"]),
    ("court_points.csv", "name,x,y\nnear_left,0.1,0.9\n,0.2,0.9\n", {}, 3, ["empty point name"]),
    ("court_points.csv", "name,x,y\nnear_left,0.1,1.9\n", {}, 2, ["outside [0, 1]"]),
    (
        "ball_3d.csv",
        "frame,x_m,y_m,z_m,segment,kind\n0,1,2,3,0,fit\n",
        {},
        2,
        ["unknown kind 'fit'", "fitted"],
    ),
    ("ball_3d.csv", "frame,x_m,y_m,z_m,segment,kind\n0,1,2,,0,fitted\n", {}, 2, ["z_m is empty"]),
    (
        "ball_3d.csv",
        "frame,x_m,y_m,z_m,segment,kind\n0,1,2,3,0,gt\n0,1,2,3,0,gt\n",
        {},
        3,
        ["duplicate (frame, kind)"],
    ),
    ("ball_3d.csv", "frame,x_m,y_m,z_m,segment,kind,sigma_m\n0,1,2,3,0,gt,-1\n", {}, 2, ["negative sigma_m"]),
    ("ball_3d.csv", "frame,x,y,z,segment,kind\n0,1,2,3,0,gt\n", {}, 1, ["missing column", "x_m"]),
]
READERS = {name: reader for name, (reader, _, _) in SAMPLES.items()}


@pytest.mark.parametrize(
    ("name", "content", "kwargs", "line", "words"),
    MALFORMED,
    ids=[f"{m[0]}-{i}" for i, m in enumerate(MALFORMED)],
)
def test_malformed_is_rejected_with_file_and_line(tmp_path, name, content, kwargs, line, words):
    path = tmp_path / name
    path.write_text(content)
    with pytest.raises(FormatError) as info:
        READERS[name](path, **kwargs)
    message = str(info.value)
    assert name in message
    assert f"line {line}:" in message and info.value.line == line
    assert "fix:" in message
    for word in words:
        assert word in message


@pytest.mark.parametrize("name", SAMPLES)
def test_missing_file(tmp_path, name):
    with pytest.raises(FormatError, match=f"{name}: file not found"):
        READERS[name](tmp_path / name)


def test_not_utf8(tmp_path):
    path = tmp_path / "events.csv"
    path.write_bytes(b"frame,event\n1,\xff\xfe\n")
    with pytest.raises(FormatError, match="UTF-8"):
        read_events_csv(path)


def test_reads_100k_rows(tmp_path):
    """Large files round-trip (speed is measured by bench/bench_clipio.py, not asserted here)."""
    n = 100_000
    vis = rng.integers(0, 4, n)
    t = BallTrack(np.arange(n), vis, np.where((vis > 0)[:, None], rng.random((n, 2)), NAN))
    path = write_ball_csv(tmp_path / "ball.csv", t)
    back = read_ball_csv(path, n_frames=n)
    assert len(back) == n
    np.testing.assert_allclose(back.xy, t.xy, atol=5e-8)


@pytest.mark.parametrize("name", SAMPLES)
def test_failed_write_leaves_previous_file_intact(tmp_path, monkeypatch, name):
    _, write, sample = SAMPLES[name]
    path = write(tmp_path / name, EMPTY[name])
    before = path.read_bytes()

    def crash(fd):
        raise OSError("disk full")

    monkeypatch.setattr(atomic.os, "fsync", crash)  # the new text is written, then the write fails
    with pytest.raises(OSError, match="disk full"):
        write(path, sample)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == [name], "no temporary file left behind"


def test_atomic_writes_get_normal_permissions(tmp_path):
    import os

    from inference.clipio import atomic_write_text

    old = os.umask(0o022)
    try:
        path = atomic_write_text(tmp_path / "x.csv", "a\n")
    finally:
        os.umask(old)
    assert path.stat().st_mode & 0o777 == 0o644


def test_events_on_one_frame_are_kept_in_order(tmp_path):
    """A floor-then-glass corner bounce written on one frame: both kept, the later row a frame later."""
    path = tmp_path / "events.csv"
    path.write_text("frame,event\n9,player_near\n3,ground\n3,wall_left\n4,net\n")
    with pytest.warns(UserWarning, match="wall_left 3 → 4"):
        ev = read_events_csv(path)
    assert ev.frame.tolist() == [3, 4, 5, 9] and ev.event.tolist() == ["ground", "wall_left", "net", "player_near"]
    path.write_text("frame,event\n8,ground\n9,net\n9,player_far\n")
    with pytest.warns(UserWarning):
        ev = read_events_csv(path, n_frames=10)  # no frame after 9: the events before move back
    assert ev.frame.tolist() == [7, 8, 9] and ev.event.tolist() == ["ground", "net", "player_far"]
