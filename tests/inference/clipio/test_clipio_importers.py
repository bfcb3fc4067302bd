"""Importers of outside formats: TrackNet tennis/badminton and the thesis CSV layout."""

import numpy as np
import pytest

from inference.clipio import (
    PADEL_6CLASS_CODES,
    FormatError,
    export_tracknet_label,
    import_thesis_ball,
    import_thesis_court_3d,
    import_thesis_court_points,
    import_thesis_hits,
    import_tracknet_badminton,
    import_tracknet_label,
)

W, H = 1280, 720
LABEL = (
    "file name,visibility,x-coordinate,y-coordinate,status\n"
    "0000.jpg,1,640,360,0\n"
    "0001.jpg,0,,,0\n"
    "0002.jpg,2,128,600,1\n"  # hit in the lower half -> player_near
    "0003.jpg,3,1280,0,2\n"  # bounce -> ground; image border is allowed
    "0005.jpg,1,100,72,1\n"  # hit in the upper half -> player_far
)


def write(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_tracknet_label(tmp_path):
    track, events = import_tracknet_label(write(tmp_path, "Label.csv", LABEL), W, H)
    assert track.frame.tolist() == [0, 1, 2, 3, 5]
    assert track.visibility.tolist() == [1, 0, 2, 3, 1]
    np.testing.assert_allclose(
        track.xy[[0, 2, 3, 4]], [[0.5, 0.5], [0.1, 600 / 720], [1.0, 0.0], [100 / W, 0.1]]
    )
    assert np.isnan(track.xy[1]).all()
    assert events.frame.tolist() == [2, 3, 5]
    assert events.event.tolist() == ["player_near", "ground", "player_far"]


def test_tracknet_label_custom_hit_label_and_no_status(tmp_path):
    path = write(tmp_path, "Label.csv", LABEL)
    _, events = import_tracknet_label(path, W, H, hit_label=lambda frame, u, v: "player_near")
    assert events.event.tolist() == ["player_near", "ground", "player_near"]
    no_status = write(
        tmp_path, "Label2.csv", "File Name,Visibility,X-coordinate,Y-coordinate\nclip1/0007.jpg,1,1,2\n"
    )
    track, events = import_tracknet_label(no_status, W, H)
    assert track.frame.tolist() == [7] and len(events) == 0


def test_tracknet_export_round_trip(tmp_path):
    track, events = import_tracknet_label(write(tmp_path, "Label.csv", LABEL), W, H)
    out = export_tracknet_label(tmp_path / "out.csv", track, events, W, H)
    track2, events2 = import_tracknet_label(out, W, H)
    assert events2 == events
    assert np.array_equal(track2.frame, track.frame) and np.array_equal(track2.visibility, track.visibility)
    np.testing.assert_allclose(track2.xy, track.xy, atol=1e-5)


B = "file name,visibility,x-coordinate,y-coordinate,status\n"
TRACKNET_BAD = [
    (B + "0000.jpg,1,640,360,0\nabc.jpg,1,1,1,0\n", 3, "no frame number in 'abc.jpg'"),
    (B + "0000.jpg,1,,360,0\n", 2, "visible ball without coordinates"),
    (B + "0000.jpg,1,640,360,0\n0000.jpg,1,640,360,0\n", 3, "duplicate frame 0"),
    (B + "0000.jpg,1,1400,360,0\n", 2, "x-coordinate = 1.09375 is outside"),
    (B + "0000.jpg,1,640,360,7\n", 2, "status 7 is not 0, 1 or 2"),
    (B + "0000.jpg,5,640,360,0\n", 2, "visibility 5"),
    (B + "0000.jpg,0,,,1\n", 2, "cannot label the hit"),
    ("file,visibility,x-coordinate,y-coordinate\n0000.jpg,1,1,1\n", 1, "missing column(s) ['file name']"),
]


@pytest.mark.parametrize(("text", "line", "words"), TRACKNET_BAD)
def test_tracknet_label_rejects(tmp_path, text, line, words):
    with pytest.raises(FormatError) as info:
        import_tracknet_label(write(tmp_path, "Label.csv", text), W, H)
    assert "Label.csv" in str(info.value) and f"line {line}:" in str(info.value)
    assert words in str(info.value)


def test_tracknet_badminton(tmp_path):
    path = write(
        tmp_path, "1_01_00_ball.csv", "Frame,Visibility,X,Y\n0,0,0,0\n1,1,640,360\n3,1,0,719\n2,0,0,0\n"
    )
    track = import_tracknet_badminton(path, W, H)
    assert track.frame.tolist() == [0, 1, 2, 3]
    assert track.visibility.tolist() == [0, 1, 0, 1]
    assert np.isnan(track.xy[[0, 2]]).all()
    np.testing.assert_allclose(track.xy[[1, 3]], [[0.5, 0.5], [0.0, 719 / 720]])


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        ("Frame,Visibility,X,Y\n0,2,1,1\n", 2, "Visibility 2 is not 0 or 1"),
        ("Frame,Visibility,X,Y\n0,1,1,1\n1,1,1,800\n", 3, "Y = 1.11111 is outside"),
        ("Frame,Visibility,X\n0,1,1\n", 1, "missing column(s) ['Y']"),
        ("Frame,Visibility,X,Y\n0,1,1,1\n-1,1,1,1\n", 3, "negative frame"),
    ],
)
def test_tracknet_badminton_rejects(tmp_path, text, line, words):
    with pytest.raises(FormatError) as info:
        import_tracknet_badminton(write(tmp_path, "x_ball.csv", text), W, H)
    assert "x_ball.csv" in str(info.value) and f"line {line}:" in str(info.value) and words in str(info.value)


def test_thesis_court_points_normalised_with_name_map(tmp_path):
    path = write(tmp_path, "court.csv", "NL_X,NL_Y,NR_X,NR_Y,FL_X,FL_Y\n0.1,0.9,0.9,0.95,,\n")
    points = import_thesis_court_points(path, name_map={"NL": "near_left", "NR": "near_right"})
    assert points.names == ["near_left", "near_right"]  # FL is empty: not visible
    np.testing.assert_allclose(points.xy, [[0.1, 0.9], [0.9, 0.95]])


def test_thesis_court_points_pixels(tmp_path):
    path = write(tmp_path, "court.csv", "A_x,A_y,B_x,B_y\n128,72,1280,720\n")
    points = import_thesis_court_points(path, width=W, height=H)
    np.testing.assert_allclose(points.xy, [[0.1, 0.1], [1.0, 1.0]])
    with pytest.raises(
        FormatError, match=r"court.csv, line 2: coordinates > 1 are pixels.*width= and height="
    ):
        import_thesis_court_points(path)


def test_thesis_court_3d(tmp_path):
    path = write(tmp_path, "court3d.csv", "NL_X,NL_Y,NL_Z,NR_X,NR_Y,NR_Z\n0,0,0,10,0,0\n")
    assert import_thesis_court_3d(path, name_map={"NL": "near_left"}) == {
        "near_left": (0.0, 0.0, 0.0),
        "NR": (10.0, 0.0, 0.0),
    }
    with pytest.raises(FormatError, match=r"court3d.csv, line 1: .*_Z columns .*import_thesis_court_3d"):
        import_thesis_court_points(path)
    with pytest.raises(FormatError, match=r"court3d.csv, line 2: point 'NL' has an empty coordinate"):
        import_thesis_court_3d(write(tmp_path, "court3d.csv", "NL_X,NL_Y,NL_Z\n0,,0\n"))


@pytest.mark.parametrize(
    ("text", "line", "words"),
    [
        ("A_X,A_Y\n0.1,0.2\n0.3,0.4\n", 3, "2 data rows, expected one"),
        ("A_X,A_Y\n", 2, "no data rows"),
        ("A_X,A_Y,B_X\n0.1,0.2,0.3\n", 1, "point 'B' has columns ['X']"),
        ("A_X,A_Y,Bee\n0.1,0.2,0.3\n", 1, "'Bee' is not <POINT>_X"),
        ("A_X,A_Y\n0.1,\n", 2, "only one coordinate"),
        ("A_X,A_Y\n0.1,oops\n", 2, "A_Y is not a number"),
        ("A_X,A_Y\n-0.1,0.5\n", 2, "outside the image"),
    ],
)
def test_thesis_court_points_rejects(tmp_path, text, line, words):
    with pytest.raises(FormatError) as info:
        import_thesis_court_points(write(tmp_path, "court.csv", text))
    assert "court.csv" in str(info.value) and f"line {line}:" in str(info.value) and words in str(info.value)


def test_thesis_ball(tmp_path):
    path = write(tmp_path, "ball.csv", "Frame,Ball,x,y\n0,1,0.5,0.25\n1,0,0,0\n2,0,,\n3,1,1.0,0.0\n")
    track = import_thesis_ball(path)
    assert track.visibility.tolist() == [1, 0, 0, 1]
    assert np.isnan(track.xy[[1, 2]]).all()
    np.testing.assert_allclose(track.xy[[0, 3]], [[0.5, 0.25], [1.0, 0.0]])


@pytest.mark.parametrize(
    ("text", "kwargs", "line", "words"),
    [
        ("Frame,Ball,x,y\n0,1,512,300\n", {}, 2, "outside [0, 1]"),
        ("Frame,Ball,x,y\n0,2,0.5,0.5\n", {}, 2, "Ball 2 is not 0 or 1"),
        ("Frame,Ball,x,y\n0,1,,0.5\n", {}, 2, "visible ball without x,y"),
        ("Frame,Ball,x,y\n0,1,0.5,0.5\n10,1,0.5,0.5\n", {"n_frames": 10}, 3, "Frame 10 is beyond the video"),
    ],
)
def test_thesis_ball_rejects(tmp_path, text, kwargs, line, words):
    with pytest.raises(FormatError) as info:
        import_thesis_ball(write(tmp_path, "balls.csv", text), **kwargs)
    assert "balls.csv" in str(info.value) and f"line {line}:" in str(info.value) and words in str(info.value)


def test_thesis_hits_default_codes(tmp_path):
    path = write(tmp_path, "hits.csv", "Frame,Hit\n0,0\n1,3\n2,0\n5,2\n4,1\n9,4\n12,5\n")
    events = import_thesis_hits(path)
    assert events.frame.tolist() == [1, 4, 5, 9, 12]
    assert events.event.tolist() == ["player_near", "wall_near", "ground", "player_far", "net"]
    assert PADEL_6CLASS_CODES[0] is None


def test_thesis_hits_custom_codes_and_unknown_code(tmp_path):
    path = write(tmp_path, "hits.csv", "Frame,Hit\n0,0\n1,3\n2,6\n")
    events = import_thesis_hits(path, code_map={0: None, 3: "ground", 6: "mesh"})
    assert events.event.tolist() == ["ground", "mesh"]
    with pytest.raises(FormatError) as info:
        import_thesis_hits(path)
    assert "hits.csv, line 4:" in str(info.value) and "unknown Hit code 6" in str(info.value)
    assert "5 net" in str(info.value)
    with pytest.raises(ValueError, match="unknown event labels"):
        import_thesis_hits(path, code_map={3: "smash"})


def test_tracknet_label_ignores_coordinates_of_invisible_rows(tmp_path):
    path = write(tmp_path, "Label.csv", B + "0000.jpg,0,0,0,0\n0001.jpg,0,-1,-1,2\n")
    track, events = import_tracknet_label(path, W, H)
    assert track.visibility.tolist() == [0, 0] and np.isnan(track.xy).all()
    assert events.frame.tolist() == [1] and events.event.tolist() == ["ground"]
