"""Hand-edited and hostile files: unknown columns kept, bad rows skipped on request, other separators named,
YAML/JSON that is not UTF-8, nested too deep or an alias bomb, and the litter of crashed saves."""
from __future__ import annotations

import os
import time

import numpy as np
import pytest

from inference.camera import Camera
from inference.clipio import (
    Clip,
    ClipInfo,
    FormatError,
    read_ball_csv,
    read_clip_yaml,
    read_court_points_csv,
    read_events_csv,
    read_inactive_balls_csv,
    write_ball_csv,
    write_court_points_csv,
    write_events_csv,
    write_inactive_balls_csv,
)
from inference.clipio.atomic import atomic_write_text, remove_stale_temp_files, stale_temp_files
from inference.clipio.structured import MAX_DEPTH, load_json, load_yaml
from inference.court import load_court

FILES = {
    "ball.csv": (read_ball_csv, write_ball_csv, "frame,visibility,x,y,note,who\n3,1,0.5,0.25,\"fast, spin\",ann\n"
                 "1,0,,,,bob\n"),
    "events.csv": (read_events_csv, write_events_csv, "frame,note,event\n9,lob,ground\n2,,player_near\n"),
    "inactive_balls.csv": (read_inactive_balls_csv, write_inactive_balls_csv,
                           "frame,ball_no,x,y,colour\n5,0,0.1,0.9,yellow\n4,1,0.2,0.8,white\n"),
    "court_points.csv": (read_court_points_csv, write_court_points_csv,
                         "name,x,y,clicked_by\nfar_left,0.1,0.2,ann\nfar_right,0.9,0.2,bob\n"),
}


@pytest.mark.parametrize("name", list(FILES))
def test_unknown_columns_survive_a_round_trip(tmp_path, name):
    read, write, text = FILES[name]
    path = tmp_path / name
    path.write_text(text)
    table = read(path)
    assert table.extra, "the unknown columns are kept"
    write(tmp_path / "again.csv", table)
    again = read(tmp_path / "again.csv")
    assert again == table
    header = (tmp_path / "again.csv").read_text().splitlines()[0].split(",")
    assert header[-len(table.extra):] == list(table.extra)


def test_unknown_columns_follow_their_rows_when_sorted(tmp_path):
    path = tmp_path / "ball.csv"
    path.write_text(FILES["ball.csv"][2])
    track = read_ball_csv(path)
    assert track.frame.tolist() == [1, 3]
    assert track.extra["note"].tolist() == ["", "fast, spin"] and track.extra["who"].tolist() == ["bob", "ann"]


@pytest.mark.parametrize("sep", [";", "\t"])
def test_other_separators_are_named(tmp_path, sep):
    path = tmp_path / "ball.csv"
    path.write_text(sep.join(["frame", "visibility", "x", "y"]) + "\n" + sep.join(["0", "1", "0.5", "0.5"]) + "\n")
    with pytest.raises(FormatError, match="separated by .* not commas") as err:
        read_ball_csv(path)
    assert err.value.line == 1 and "comma-separated" in err.value.fix


def test_bad_rows_are_skipped_only_on_request(tmp_path):
    path = tmp_path / "ball.csv"
    path.write_text("frame,visibility,x,y\n0,1,0.5,0.5\n1,1,1.2,0.5\n# a comment\n0,1,0.4,0.4\n2,1,0.3,0.3\n")
    with pytest.raises(FormatError, match="line 4"):  # the comment line has 1 field
        read_ball_csv(path)
    skipped: list[FormatError] = []
    track = read_ball_csv(path, skipped=skipped)
    assert track.frame.tolist() == [0, 2]
    assert sorted(e.line for e in skipped) == [3, 4, 5]  # x = 1.2, the comment, the duplicate frame 0
    assert any("outside [0, 1]" in str(e) for e in skipped) and any("duplicate frame 0" in str(e) for e in skipped)


def test_header_errors_are_not_skipped(tmp_path):
    path = tmp_path / "events.csv"
    path.write_text("frame,evnt\n1,ground\n")
    with pytest.raises(FormatError, match="rename 'evnt' to 'event'"):
        read_events_csv(path, skipped=[])


def test_events_can_be_held_to_the_courts_vocabulary(tmp_path):
    path = tmp_path / "events.csv"
    path.write_text("frame,event\n1,ground\n4,wall_left\n")
    assert len(read_events_csv(path)) == 2  # every label of the format
    tennis = load_court("tennis").annotation_labels
    with pytest.raises(FormatError, match="line 3: unknown event 'wall_left'") as err:
        read_events_csv(path, labels=tennis)
    assert "player_near" in err.value.fix


# ----------------------------------------------------------------------------------- YAML and JSON
BAD_YAML = {
    "latin-1": ("sport: pádel\n".encode("latin-1"), "not UTF-8"),
    "deep flow": (b"sport: " + b"[" * 5000, f"nested deeper than {MAX_DEPTH}"),
    "deep block": ("".join("  " * i + f"k{i}:\n" for i in range(1500)).encode(), "nested deeper"),
    "bad date": (b"sport: 2001-13-45\n", "not valid YAML"),
    "alias bomb": (("a: &a [x, x, x, x, x, x, x, x, x, x]\n"
                    + "".join(f"{c}: &{c} [{', '.join([f'*{p}'] * 10)}]\n"
                              for p, c in zip("abcdefgh", "bcdefghi"))).encode(), "expands to more than"),
    "self reference": (b"a: &a [1, *a]\n", "contains itself"),
}


@pytest.mark.parametrize("case", list(BAD_YAML))
def test_yaml_readers_raise_only_format_errors(tmp_path, case):
    data, words = BAD_YAML[case]
    for name, read in [("clip.yaml", read_clip_yaml), ("camera.yaml", Camera.load), ("court.yaml", load_court),
                       ("any.yaml", load_yaml)]:
        path = tmp_path / name
        path.write_bytes(data)
        t0 = time.process_time()
        with pytest.raises(FormatError, match=words) as err:
            read(path)
        assert err.value.path == path
        assert time.process_time() - t0 < 5.0, f"{name}: {case} took too long"


def test_json_readers_raise_only_format_errors(tmp_path):
    from inference.pipeline.state import RunState
    from labeler.review.shots import read_segments

    path = tmp_path / "segments.json"
    for data, words in [(b"\xff\xfe{}", "not UTF-8"), (b"[" * 100_000, "nested deeper"),
                        (b'{"segments": [1,', "not valid JSON")]:
        path.write_bytes(data)
        with pytest.raises(FormatError, match=words):
            load_json(path)
        with pytest.raises(FormatError, match=words):
            read_segments(path)
    state = tmp_path / ".rally3d" / "pipeline.json"
    state.parent.mkdir()
    state.write_bytes(b"\xff" * 10)
    assert RunState(tmp_path).stages == {}  # a damaged record only costs a re-run


# --------------------------------------------------------------------------------- temporary files
def test_stale_temp_files_of_crashed_saves_are_found_and_removed(tmp_path):
    atomic_write_text(tmp_path / "events.csv", "frame,event\n")
    litter = tmp_path / ".events.csv.abc123.tmp"
    litter.write_text("frame,ev")
    fresh = tmp_path / ".ball.csv.xyz.tmp"  # a save in progress right now: left alone
    fresh.write_text("frame")
    old = time.time() - 3600
    os.utime(litter, (old, old))
    assert stale_temp_files(tmp_path) == [litter]
    assert remove_stale_temp_files(tmp_path) == [litter]
    assert not litter.exists() and fresh.exists() and (tmp_path / "events.csv").exists()


def test_clip_reads_pass_the_options_through(tmp_path):
    clip = Clip.create(tmp_path / "c", ClipInfo(sport="padel", fps=30, width=64, height=48, video="video.mp4",
                                                n_frames=10))
    clip.events_path.write_text("frame,event\n1,ground\n20,net\n")
    skipped: list[FormatError] = []
    events = clip.read_events(skipped=skipped)
    assert events.frame.tolist() == [1] and "beyond the video" in str(skipped[0])
    np.testing.assert_array_equal(clip.read_events(labels=["ground", "net"], skipped=[]).frame, [1])


def test_the_fix_for_a_file_not_in_utf8_names_its_type(tmp_path):
    """A YAML, JSON or XML file that is not UTF-8 is to be saved as UTF-8 YAML / JSON / XML — not "as UTF-8
    CSV", which every reader said."""
    from inference.clipio.csvtable import read_text

    latin = "sport: pádel\n".encode("latin-1")
    for name, read, kind in [("clip.yaml", read_clip_yaml, "YAML"), ("any.yml", load_yaml, "YAML"),
                             ("segments.json", load_json, "JSON"), ("annotations.xml", read_text, "XML"),
                             ("ball.csv", read_text, "CSV"), ("notes", read_text, "text")]:
        path = tmp_path / name
        path.write_bytes(latin)
        with pytest.raises(FormatError, match="not UTF-8") as err:
            read(path)
        assert err.value.fix == f"save the file as UTF-8 {kind}", (name, err.value.fix)
