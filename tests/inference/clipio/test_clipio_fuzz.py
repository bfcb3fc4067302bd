"""Fuzz tests (hypothesis) of every reader of the clip folder: whatever the file holds, a reader returns a
valid object or raises :class:`FormatError` — never another exception (and never hangs).

Each reader gets random bytes, and files shaped like the real ones (the right header, cells drawn from
numbers, labels, quotes, separators and junk; YAML/JSON documents with the real keys and random values).
The default profile is derandomized (the same examples on every run, so the suite cannot flake); for a
longer random search::

    RALLY3D_FUZZ=5000 .venv/bin/python -m pytest tests/inference/clipio/test_clipio_fuzz.py
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
import yaml

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from inference.camera import Camera  # noqa: E402
from inference.clipio import (  # noqa: E402
    FormatError,
    Manifest,
    import_thesis_ball,
    import_thesis_court_3d,
    import_thesis_court_points,
    import_thesis_hits,
    import_tracknet_badminton,
    import_tracknet_label,
    read_ball_3d_csv,
    read_ball_csv,
    read_clip_yaml,
    read_court_points_csv,
    read_events_csv,
    read_inactive_balls_csv,
    read_players_csv,
)
from inference.clipio.players import BASE_COLUMNS, KP_COLUMNS  # noqa: E402
from inference.clipio.structured import load_json  # noqa: E402
from inference.court import CONF_DIR, load_court  # noqa: E402

N = int(os.environ.get("RALLY3D_FUZZ", "0"))
settings.register_profile("suite", max_examples=60, derandomize=True, deadline=None, database=None,
                          suppress_health_check=list(HealthCheck))
settings.register_profile("search", max_examples=max(N, 1), deadline=None, database=None,
                          suppress_health_check=list(HealthCheck))
FUZZ = settings.get_profile("search" if N else "suite")

CELLS = ["", "0", "1", "2", "3", "7", "-1", "0.5", "1.2", "-0.0", "1e-7", "1e308", "1e400", "-1e400", "nan",
         "NaN", "inf", "-inf", "2.5", "99999999999999999999999", "0x10", "1_000", " 4 ", "ground", "net",
         "player_near", "wall_left", "fitted", "contact", "gt", "near", "far", "far_left", "net_post_left_top",
         '"', '""', '"a,b"', "é", "\x00", "\t", ";", "#", "<script>", "a" * 300]
cell = st.one_of(st.sampled_from(CELLS), st.text(max_size=12))


def csv_text(header: list[str]) -> st.SearchStrategy[str]:
    """A CSV file with ``header`` (sometimes altered) and rows of random cells."""
    head = st.one_of(
        st.just(header),
        st.lists(st.sampled_from([*header, "note", "x ", "Frame", ""]), min_size=0, max_size=len(header) + 2),
    )
    width = len(header)
    rows = st.lists(st.lists(cell, min_size=max(width - 1, 0), max_size=width + 1), max_size=8)
    sep = st.sampled_from([",", ",", ",", ";", "\t"])
    eol = st.sampled_from(["\n", "\r\n", "\r"])
    return st.builds(lambda h, r, s, e: e.join(s.join(row) for row in [h, *r]) + e, head, rows, sep, eol)


def file_bytes(text: st.SearchStrategy[str]) -> st.SearchStrategy[bytes]:
    """The file's bytes: a shaped text (UTF-8, sometimes with a BOM or cut short) or random bytes."""
    shaped = st.builds(lambda t, bom, cut: (b"\xef\xbb\xbf" if bom else b"") + t.encode("utf-8")[:cut],
                       text, st.booleans(), st.integers(1, 4000))
    return st.one_of(shaped, shaped, st.binary(max_size=300))


def only_format_errors(read, path: Path, data: bytes) -> None:
    path.write_bytes(data)
    try:
        read(path)
    except FormatError:
        pass


CSV_READERS = {
    "ball.csv": (lambda p: read_ball_csv(p, n_frames=50), ["frame", "visibility", "x", "y"]),
    "ball.csv skipping": (lambda p: read_ball_csv(p, skipped=[]), ["frame", "visibility", "x", "y"]),
    "inactive_balls.csv": (lambda p: read_inactive_balls_csv(p, n_frames=50), ["frame", "ball_no", "x", "y"]),
    "events.csv": (lambda p: read_events_csv(p, n_frames=50, labels=["ground", "net"]), ["frame", "event"]),
    "events.csv skipping": (lambda p: read_events_csv(p, skipped=[]), ["frame", "event"]),
    "court_points.csv": (lambda p: read_court_points_csv(p, known_names=["far_left", "far_right"]),
                         ["name", "x", "y"]),
    "court_points.csv skipping": (lambda p: read_court_points_csv(p, skipped=[]), ["name", "x", "y"]),
    "ball_3d.csv": (lambda p: read_ball_3d_csv(p, n_frames=50),
                    ["frame", "x_m", "y_m", "z_m", "segment", "kind", "sigma_m"]),
    "players.csv": (lambda p: read_players_csv(p, n_frames=50), list(BASE_COLUMNS + KP_COLUMNS)),
    "tracknet label": (lambda p: import_tracknet_label(p, 1280, 720),
                       ["file name", "visibility", "x-coordinate", "y-coordinate", "status"]),
    "tracknet badminton": (lambda p: import_tracknet_badminton(p, 1280, 720), ["Frame", "Visibility", "X", "Y"]),
    "thesis court points": (lambda p: import_thesis_court_points(p, width=1280, height=720),
                            ["far_left_x", "far_left_y", "far_right_x", "far_right_y"]),
    "thesis court 3d": (import_thesis_court_3d, ["far_left_x", "far_left_y", "far_left_z"]),
    "thesis ball": (lambda p: import_thesis_ball(p, n_frames=50), ["Frame", "Ball", "x", "y"]),
    "thesis hits": (lambda p: import_thesis_hits(p, n_frames=50), ["Frame", "Hit"]),
}


@pytest.mark.filterwarnings("error::RuntimeWarning")  # a silent overflow or bad cast is a bug too
@pytest.mark.parametrize("name", list(CSV_READERS))
def test_csv_readers_raise_only_format_errors(name, tmp_path):
    read, header = CSV_READERS[name]

    @FUZZ
    @given(data=file_bytes(csv_text(header)))
    def run(data: bytes) -> None:
        only_format_errors(read, tmp_path / "file.csv", data)

    run()


# -------------------------------------------------------------------------------------- YAML, JSON
scalar = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20), st.floats(allow_nan=True),
                   st.sampled_from(CELLS), st.text(max_size=10))
value = st.recursive(scalar, lambda inner: st.one_of(st.lists(inner, max_size=5),
                                                      st.dictionaries(st.text(max_size=6), inner, max_size=4)),
                     max_leaves=30)


def yaml_doc(keys: list[str], base: dict | None = None) -> st.SearchStrategy[str]:
    """A YAML mapping over ``keys`` (from ``base`` where given, each possibly replaced by a random value)."""
    def build(chosen: dict, drop: list[str]) -> str:
        doc = {**(base or {}), **chosen}
        for k in drop:
            doc.pop(k, None)
        return yaml.safe_dump(doc, allow_unicode=True)

    return st.one_of(
        st.builds(build, st.dictionaries(st.sampled_from(keys), value, max_size=len(keys)),
                  st.lists(st.sampled_from(keys), max_size=2)),
        st.text(max_size=200),
    )


def test_clip_yaml_raises_only_format_errors(tmp_path):
    base = {"sport": "padel", "fps": 30, "width": 1280, "height": 720, "video": "video.mp4"}

    @FUZZ
    @given(data=file_bytes(yaml_doc([*base, "n_frames", "court", "split", "extra"], base)))
    def run(data: bytes) -> None:
        only_format_errors(read_clip_yaml, tmp_path / "clip.yaml", data)

    run()


def test_camera_yaml_raises_only_format_errors(tmp_path):
    sample = Path(__file__).resolve().parents[3] / "datasets" / "sample" / "padel_sample" / "gt" / "camera.yaml"
    base = yaml.safe_load(sample.read_text())

    @FUZZ
    @given(data=file_bytes(yaml_doc(list(base), base)))
    def run(data: bytes) -> None:
        only_format_errors(Camera.load, tmp_path / "camera.yaml", data)

    run()


@pytest.mark.parametrize("court", ["padel", "tennis"])
def test_court_yaml_raises_only_format_errors(court, tmp_path):
    base = yaml.safe_load((CONF_DIR / "court" / f"{court}.yaml").read_text())

    @FUZZ
    @given(data=file_bytes(yaml_doc(list(base), base)))
    def run(data: bytes) -> None:
        only_format_errors(load_court, tmp_path / "court.yaml", data)

    run()


def test_manifest_raises_only_format_errors(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "a" / "clip.yaml").write_text("sport: padel\n")
    base = {"name": "d", "sport": "padel", "clips": [{"path": "a", "split": "train"}]}

    @FUZZ
    @given(data=file_bytes(yaml_doc(["name", "sport", "clips", "source"], base)))
    def run(data: bytes) -> None:
        only_format_errors(Manifest.load, tmp_path / "manifest.yaml", data)

    run()


def test_json_readers_raise_only_format_errors(tmp_path):
    from inference.pipeline.state import RunState
    from labeler.review.shots import read_segments

    doc = st.one_of(st.builds(json.dumps, st.dictionaries(st.sampled_from(["segments", "method", "stages"]), value,
                                                          max_size=3)),
                    st.text(max_size=200))
    (tmp_path / ".rally3d").mkdir()

    @FUZZ
    @given(data=file_bytes(doc))
    def run(data: bytes) -> None:
        only_format_errors(load_json, tmp_path / "x.json", data)
        only_format_errors(read_segments, tmp_path / "segments.json", data)
        (tmp_path / ".rally3d" / "pipeline.json").write_bytes(data)
        RunState(tmp_path)  # never raises: a damaged record only costs a re-run

    run()


def test_clip_folder_as_a_whole(tmp_path):
    """``rally3d check`` over a clip whose files are all fuzzed: a report, never a traceback."""
    from inference.cli import main

    sample = Path(__file__).resolve().parents[3] / "datasets" / "sample" / "padel_sample"
    clip = tmp_path / "clip"
    shutil.copytree(sample, clip, ignore=shutil.ignore_patterns("video.mp4", "gt"))

    @settings(FUZZ, max_examples=min(FUZZ.max_examples, 20))
    @given(ball=file_bytes(csv_text(["frame", "visibility", "x", "y"])),
           events=file_bytes(csv_text(["frame", "event"])))
    def run(ball: bytes, events: bytes) -> None:
        (clip / "ball.csv").write_bytes(ball)
        (clip / "events.csv").write_bytes(events)
        assert main(["check", str(clip)]) in (0, 1)

    run()
