"""The review without a browser: playback state, overlay drawing, scene geometry, camera presets, loading
errors, the export (.viser + HTML + CSV) and the CLI, on the reconstructed sample clip."""
from __future__ import annotations

import csv
import io
import shutil

import msgspec
import numpy as np
import pytest
import zstandard
from review_fixtures import reconstructed_clip, sample_events, sample_shots  # noqa: F401  (fixture)

from inference.clipio import FormatError
from inference.court import load_court, points_in_polygon
from labeler.review.data import ReviewData
from labeler.review.export import export_review
from labeler.review.overlay import draw_overlay, project_segments
from labeler.review.playback import Playback
from labeler.review.scene import (
    BALL_RGB,
    LABEL_CHAR_PX,
    LABEL_LINE_PX,
    camera_presets,
    contact_labels,
    spread_labels,
    trail_segments,
    triangulate_polygon,
)


@pytest.fixture(scope="module")
def data(reconstructed_clip) -> ReviewData:
    return ReviewData.load(reconstructed_clip)


# --------------------------------------------------------------------------------------------- playback
def test_playback_advances_wraps_and_clamps():
    pb = Playback(first=18, last=233, fps=30.0)
    assert pb.frame == 18 and pb.advance(1.0) == 18  # paused
    pb.playing = True
    assert pb.advance(0.5) == 33
    pb.set_speed(0.25)
    assert pb.advance(2.0) == 48
    pb.seek(230)
    pb.set_speed(1.0)
    assert pb.advance(0.2) == 18 + (236 - 18) % 216  # wrapped to the start
    pb.loop = False
    pb.seek(230)
    assert pb.advance(1.0) == 233 and not pb.playing
    assert pb.seek(-5) == 18 and pb.seek(10_000) == 233
    assert pb.step(-1) == 232 and not pb.playing
    with pytest.raises(ValueError, match="empty playback range"):
        Playback(first=5, last=4, fps=30)
    with pytest.raises(ValueError, match="speed"):
        pb.set_speed(0)


# ----------------------------------------------------------------------------------------------- scene
@pytest.mark.parametrize("plane", [p for p in load_court("padel").planes])
def test_triangulation_covers_every_court_polygon(plane):
    """Every padel plane (including the stepped side glass) triangulates into M-2 triangles whose area is the
    polygon's and whose centroids lie inside it."""
    poly = plane.polygon
    tris = triangulate_polygon(poly)
    assert tris.shape == (len(poly) - 2, 3)
    a = poly[tris]
    e1, e2 = a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]
    areas = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    shoelace = 0.5 * abs(np.dot(poly[:, 0], np.roll(poly[:, 1], -1)) - np.dot(poly[:, 1], np.roll(poly[:, 0], -1)))
    assert areas.sum() == pytest.approx(shoelace)
    assert points_in_polygon(a.mean(axis=1), poly).all()


def test_trail_fades_to_the_ball_colour():
    xyz = np.c_[np.arange(5.0), np.zeros(5), np.ones(5)]
    segs, cols = trail_segments(xyz)
    assert segs.shape == cols.shape == (4, 2, 3)
    assert tuple(cols[-1, 1]) == BALL_RGB and tuple(cols[0, 0]) != BALL_RGB


def test_broadcast_preset_is_the_clip_camera(data):
    presets = camera_presets(data.camera, data.court)
    assert set(presets) == {"broadcast", "top", "behind near team", "behind far team"}
    b = presets["broadcast"]
    assert np.allclose(b.position, data.camera.centre)
    # the look-at point projects to the image centre; "up" points to smaller image rows
    px = data.camera.project(np.array(b.look_at))[0]
    assert np.allclose(px, data.camera.K[:2, 2], atol=1e-6)
    up_px = data.camera.project(np.array(b.look_at) + 0.5 * np.array(b.up))[0]
    assert up_px[1] < px[1]
    assert presets["behind near team"].position[1] < 0 < presets["behind far team"].position[1] - data.court.size[1]


# --------------------------------------------------------------------------------------------- overlay
def test_overlay_draws_the_reprojected_ball_and_court(data):
    frame = np.zeros((720, 1280, 3), np.uint8)
    f = 45
    img = draw_overlay(frame, data.camera, data.court, ball_xyz=data.ball_at(f), out_width=640)
    assert img.shape == (360, 640, 3) and not frame.any()  # input untouched
    u, v = data.camera.project(data.ball_at(f))[0] * 0.5
    patch = img[int(v) - 1: int(v) + 2, int(u) - 1: int(u) + 2].reshape(-1, 3)
    assert (np.abs(patch.astype(int) - BALL_RGB).max(axis=1) < 40).any()
    # the far baseline's projected midpoint is painted
    poly = project_segments(data.camera, data.court.lines["paint"][2:3])[0] * 0.5
    mu, mv = np.round(poly[len(poly) // 2]).astype(int)
    assert img[mv - 1: mv + 2, mu - 1: mu + 2].max() > 150


# ------------------------------------------------------------------------------------------ data errors
def test_clear_errors_for_missing_inputs(reconstructed_clip, tmp_path):
    with pytest.raises(FormatError, match="clip.yaml"):
        ReviewData.load(tmp_path)
    clip = tmp_path / "c"
    shutil.copytree(reconstructed_clip, clip)
    (clip / "segments.json").write_text("{not json")
    with pytest.raises(FormatError, match="segments.json.*not valid JSON"):
        ReviewData.load(clip)
    (clip / "ball_3d.csv").unlink()
    with pytest.raises(FormatError, match="rally3d reconstruct"):
        ReviewData.load(clip)
    (clip / "camera.yaml").unlink()
    with pytest.raises(FormatError, match="rally3d calibrate"):
        ReviewData.load(clip)


def test_review_without_video_shows_placeholder(reconstructed_clip, tmp_path):
    clip = tmp_path / "novideo"
    shutil.copytree(reconstructed_clip, clip)
    (clip / "video.mp4").write_bytes(b"not a video")
    with pytest.warns(UserWarning, match="video cannot be opened"):
        d = ReviewData.load(clip)
    assert not d.video_ok and len(d.analysis.shots) == len(sample_shots())  # one shot per racket hit


# ---------------------------------------------------------------------------------------------- export
def read_viser(path) -> dict:
    """Decode a .viser recording: 8-byte size, zstd stream of (8-byte msgpack length, msgpack, buffers)."""
    raw = path.read_bytes()
    inner = zstandard.ZstdDecompressor().decompress(raw[8:], max_output_size=int.from_bytes(raw[:8], "little"))
    n = int.from_bytes(inner[:8], "little")
    return msgspec.msgpack.decode(inner[8: 8 + n])


def test_export_writes_a_playable_replay_and_the_shot_table(data, tmp_path):
    res = export_review(data, tmp_path / "out", progress=False)
    assert res.n_steps == data.last_frame - data.first_frame + 1
    rec = read_viser(res.replay)
    assert rec["durationSeconds"] == pytest.approx(res.n_steps / data.fps)
    kinds = [m[1]["type"] for m in rec["messages"]]
    assert "IcosphereMessage" in kinds and "MeshMessage" in kinds and "LineSegmentsMessage" in kinds
    times = [m[0] for m in rec["messages"]]
    assert times == sorted(times) and times[-1] > 0.9 * rec["durationSeconds"]  # the ball keeps moving
    html = res.html.read_text()
    assert "window.__VISER_EMBED_DATA__=" in html and html.index("__VISER_EMBED_DATA__") < html.index("</head>")
    rows = list(csv.DictReader(io.StringIO(res.shots_csv.read_text())))
    expected = sample_shots()  # one shot per racket hit of events.csv: (hit frame, team, has a floor bounce)
    assert len(rows) == len(data.analysis.shots) == len(expected)
    assert [(int(r["hit_frame"]), r["team"]) for r in rows] == [(f, team) for f, team, _ in expected]
    # every shot with a floor bounce is called in (the far lob too, above the picture for 59 frames); the
    # last, cut by the clip's end before its bounce, has no call
    assert [r["call"] for r in rows] == ["in" if bounced else "" for *_, bounced in expected]
    # the page's side panel: the clip's video copied beside it, the shot table, the frame read-outs
    assert (tmp_path / "out" / "video.mp4").read_bytes() == data.clip.video_path.read_bytes()
    assert html.count('<tr><td>') == len(expected) and 'id="rally3d-video" src="video.mp4"' in html
    assert "rally3d-video-frame" in html and f'"hits": {[s.hit.frame for s in data.analysis.shots]}' in html
    labels = [m[1]["updates"]["text"] for m in rec["messages"] if m[1]["type"] == "SceneNodeUpdateMessage"
              and m[1]["name"] == "/replay/frame" and "text" in m[1]["updates"]]
    assert labels[0] == f"frame {data.first_frame}" and labels[-1] == f"frame {data.last_frame}"


def boxes_of(labels, project) -> list[tuple[float, float, float, float]]:
    out = []
    for lab in labels:
        u, v = project((lab.anchor + (0, 0, lab.lift))[None])[0]
        half = 0.5 * LABEL_CHAR_PX * len(lab.text)
        out.append((u - half, v - LABEL_LINE_PX, u + half, v))
    return out


def overlaps(boxes) -> list[tuple[int, int]]:
    return [(i, j) for i, a in enumerate(boxes) for j, b in enumerate(boxes[:i])
            if a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]]


def test_contact_labels_do_not_overlap_in_the_broadcast_view(data):
    project = data.camera.project
    labels = contact_labels(data.analysis, project)
    # one label per event from the first racket hit on (every hit and every contact after it; the serve's
    # drop before it has none), each with its shot number and frame
    first_hit = min(f for f, _, _ in sample_shots())
    assert len(labels) == sum(f >= first_hit for f, _ in sample_events())
    assert all("@" in lab.text for lab in labels)
    plain = contact_labels(data.analysis)  # without spreading, the sample's labels do cover each other
    assert overlaps(boxes_of(plain, project))
    assert not overlaps(boxes_of(labels, project))
    # three labels on one spot are stacked, each lifted above the one before
    pts = np.zeros((3, 3))
    lifts = spread_labels(pts, ["in +20 cm"] * 3, project)
    assert lifts[0] < lifts[1] < lifts[2]


def test_cli_export(reconstructed_clip, tmp_path, capsys):
    from inference.cli import main

    assert main(["review", str(reconstructed_clip), "--export", str(tmp_path / "x"), "--stride", "3"]) == 0
    out = capsys.readouterr().out
    assert "centre service line" in out and "replay.viser" in out
    assert (tmp_path / "x" / "replay.viser").stat().st_size > 1000
    assert (tmp_path / "x" / "shots.csv").read_text().count("\n") == 1 + len(sample_shots())  # header + shots
    assert main(["review", str(tmp_path / "nothing")]) == 1
    assert "clip.yaml" in capsys.readouterr().err


def test_tick_keeps_a_play_click_still_on_its_way_and_unchecks_at_the_end():
    """The browser's play box is checked (value True) before its callback starts the playback: the
    background tick must not read that as "stopped at the end" and uncheck it (a lost click)."""
    import threading
    from types import SimpleNamespace

    from labeler.review.app import Session
    from labeler.review.playback import Playback

    class Stub(SimpleNamespace):
        def render(self):
            self.renders += 1

        def _set_play(self, playing):
            self.playback.playing = playing
            self.panel.play.value = playing

    s = Stub(lock=threading.Lock(), playback=Playback(0, 10, 10.0, loop=False), panel=SimpleNamespace(play=SimpleNamespace(value=True)),
             renders=0, paged=False)  # the server's clock: before the page's player attaches
    Session.tick(s, 0.1)                         # the click's value arrived, its callback not yet
    assert s.panel.play.value is True and s.renders == 0
    s.playback.playing = True                    # the callback runs
    Session.tick(s, 0.5)
    assert s.playback.frame == 5 and s.panel.play.value is True and s.renders == 1
    Session.tick(s, 2.0)                         # past the last frame: stops there and unchecks the box
    assert s.playback.frame == 10 and not s.playback.playing and s.panel.play.value is False
