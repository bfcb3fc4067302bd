"""The one rule for files a person may have edited: a command that replaces ball.csv, events.csv,
players.csv, camera.yaml or court_points.csv keeps the previous version in ``.rally3d/backup/`` and says
so; ``--start``/``--end`` of detect, events and players replace only the stretch's rows."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from inference.cli import main
from inference.clipio import BallTrack, Clip, HitEvents, PlayerTracks, read_ball_csv, read_events_csv
from inference.clipio.atomic import replace_keeping_backup
from inference.clipio.span import Span, merge_span

SAMPLE = Path(__file__).resolve().parents[2] / "datasets" / "sample" / "padel_sample"


def _sample(tmp_path: Path) -> Path:
    clip = tmp_path / "clip"
    shutil.copytree(SAMPLE, clip)
    return clip


def _backups(clip: Path, name: str) -> list[Path]:
    return sorted((clip / ".rally3d" / "backup").glob(f"{name}.*"))


# ------------------------------------------------------------------------------------------- the helper
def test_replace_keeping_backup_copies_only_a_different_file(tmp_path):
    target = tmp_path / "ball.csv"
    target.write_text("mine\n")
    lines: list[str] = []
    r = replace_keeping_backup(target, lambda p: p.write_text("new\n"), log=lines.append)
    assert r.changed and target.read_text() == "new\n"
    assert r.backup is not None and r.backup.read_text() == "mine\n"
    assert r.backup.parent == tmp_path / ".rally3d" / "backup"
    assert lines and str(r.backup) in lines[0]
    again = replace_keeping_backup(target, lambda p: p.write_text("new\n"), log=lines.append)
    assert not again.changed and again.backup is None and len(lines) == 1
    assert not list(tmp_path.glob(".*.tmp*"))  # no litter


def test_replace_keeping_backup_leaves_the_old_file_when_the_writer_fails(tmp_path):
    target = tmp_path / "events.csv"
    target.write_text("mine\n")

    def broken(p: Path) -> None:
        p.write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        replace_keeping_backup(target, broken, log=None)
    assert target.read_text() == "mine\n" and not list(tmp_path.glob(".*.tmp*"))


# ------------------------------------------------------------------------------------------ merge_span
def test_merge_span_keeps_the_rows_outside_the_stretch():
    old = BallTrack(frame=[0, 1, 5, 9], visibility=[1, 1, 1, 1], xy=[[0.1, 0.1]] * 4)
    new = BallTrack(frame=[0, 4, 5, 6, 9], visibility=[0, 1, 0, 1, 0],
                    xy=[[np.nan, np.nan], [0.5, 0.5], [np.nan, np.nan], [0.6, 0.6], [np.nan, np.nan]])
    out = merge_span(old, new, 4, 7)
    assert out.frame.tolist() == [0, 1, 4, 5, 6, 9]
    assert out.visibility.tolist() == [1, 1, 1, 0, 1, 1]
    ev = merge_span(HitEvents([2, 8], ["ground", "player_near"]), HitEvents([5], ["player_far"]), 4, 7)
    assert ev.frame.tolist() == [2, 5, 8] and ev.event.tolist() == ["ground", "player_far", "player_near"]


def test_merge_span_renumbers_new_players():
    def tracks(frames, ids):
        n = len(frames)
        return PlayerTracks(frames, ids, ["near"] * n, np.ones(n), np.full((n, 4), 0.5), np.full((n, 17, 3), 0.5),
                            np.zeros((n, 2)))
    out = merge_span(tracks([0, 0, 9], [0, 1, 0]), tracks([4, 5], [0, 0]), 3, 8)
    assert out.frame.tolist() == [0, 0, 4, 5, 9]
    assert sorted(set(out.player_id[(out.frame >= 3) & (out.frame < 8)].tolist())) == [2]


def test_span_rejects_bad_bounds():
    with pytest.raises(ValueError, match="after --start"):
        Span(3, 2)
    with pytest.raises(ValueError, match="past the end"):
        Span(20, None).frames(30, 240)
    assert Span(1, 2).frames(30, 240) == (30, 60)


# --------------------------------------------------------------------------------------------- commands
def test_detect_backs_up_a_hand_labelled_ball_csv_and_merges_a_stretch(tmp_path, capsys):
    clip = _sample(tmp_path)
    mine = (clip / "ball.csv").read_text()
    hand = read_ball_csv(clip / "ball.csv")
    assert main(["detect", str(clip), "--start", "1", "--end", "1.5"]) == 0
    out = capsys.readouterr().out
    [copy] = _backups(clip, "ball.csv")
    assert copy.read_text() == mine and str(copy) in out and "frames 30-44" in out
    new = read_ball_csv(clip / "ball.csv")
    outside = (new.frame < 30) | (new.frame >= 45)
    assert new.frame[outside].tolist() == hand.frame[(hand.frame < 30) | (hand.frame >= 45)].tolist()
    assert np.allclose(new.xy[outside], hand.xy[(hand.frame < 30) | (hand.frame >= 45)], equal_nan=True)
    assert set(range(30, 45)) <= set(new.frame.tolist())


def test_detect_out_of_range_and_unknown_arguments_name_the_command(tmp_path, capsys):
    clip = _sample(tmp_path)
    assert main(["detect", str(clip), "--start", "30"]) == 1
    assert "past the end" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:
        main(["detect", str(clip), "--strat", "3"])
    assert e.value.code == 2
    assert "rally3d detect" in capsys.readouterr().err


def test_events_backs_up_a_hand_labelled_events_csv(tmp_path, capsys):
    clip = _sample(tmp_path)
    mine = (clip / "events.csv").read_text()
    hand = read_events_csv(clip / "events.csv")
    assert main(["events", str(clip), "--no-players", "--start", "2", "--end", "5"]) == 0
    out = capsys.readouterr().out
    [copy] = _backups(clip, "events.csv")
    assert copy.read_text() == mine and str(copy) in out and "no rally.yaml" in out
    new = read_events_csv(clip / "events.csv")
    keep_old = (hand.frame < 60) | (hand.frame >= 150)
    assert set(hand.frame[keep_old].tolist()) <= set(new.frame.tolist())
    assert not (clip / "rally.yaml").exists()
    assert main(["events", str(clip), "--no-players"]) == 0  # the whole clip: a second backup, rally.yaml
    assert len(_backups(clip, "events.csv")) == 2 and (clip / "rally.yaml").is_file()


def test_players_backs_up_players_csv(tmp_path, capsys):
    clip = _sample(tmp_path)
    shutil.copy(clip / "gt" / "camera.yaml", clip / "camera.yaml")
    shutil.copy(clip / "gt" / "players.csv", clip / "players.csv")
    mine = (clip / "players.csv").read_text()
    code = main(["players", str(clip), "--pose", "movenet", "--start", "0", "--end", "0.2"])
    if code != 0 and "unavailable" in capsys.readouterr().err:
        pytest.skip("MoveNet is not installed")
    assert code == 0
    out = capsys.readouterr().out
    [copy] = _backups(clip, "players.csv")
    assert copy.read_text() == mine and str(copy) in out and "frames 0-5" in out
    new = Clip(clip).read_players()
    hand = Clip(clip).read_players(gt=True)
    assert new.frame[new.frame >= 6].tolist() == hand.frame[hand.frame >= 6].tolist()


def test_calibrate_backs_up_camera_yaml(tmp_path, capsys):
    clip = _sample(tmp_path)
    shutil.copy(clip / "gt" / "camera.yaml", clip / "camera.yaml")
    mine = (clip / "camera.yaml").read_text()
    assert main(["calibrate", str(clip)]) == 0
    out = capsys.readouterr().out
    [copy] = _backups(clip, "camera.yaml")
    assert copy.read_text() == mine and str(copy) in out


def test_infer_new_court_points_retire_a_hand_made_camera(tmp_path, capsys):
    """New points in place must not leave the old camera.yaml beside them (points and camera disagree)."""
    clip = _sample(tmp_path)
    shutil.copy(clip / "gt" / "camera.yaml", clip / "camera.yaml")
    from dataclasses import replace

    from inference.camera import Camera

    cam = Camera.load(clip / "camera.yaml")
    replace(cam, P=cam.P * 1.0001).save(clip / "camera.yaml")  # a hand-made camera, not from these points
    mine = (clip / "camera.yaml").read_text()
    lines = (clip / "court_points.csv").read_text().splitlines()
    other = tmp_path / "points.csv"
    other.write_text("\n".join(lines[:-1]) + "\n")
    code = main(["infer", str(clip), "--court-points", str(other), "--no-progress", "--pose", "none",
                 "--only", "camera"])
    out = capsys.readouterr().out
    assert code == 0
    [copy] = _backups(clip, "camera.yaml")
    assert copy.read_text() == mine and "calibrated from" in out
    assert (clip / "camera.yaml").read_text() != mine  # recalibrated from the new points


# ------------------------------------------------------------------------------- cameras that see no court
def _looking_away(cam):
    """``cam`` turned 180° about the vertical through its centre: the court is behind it."""
    from dataclasses import replace

    R2 = cam.R @ np.diag([-1.0, -1.0, 1.0])
    t2 = -R2 @ cam.centre
    return replace(cam, P=cam.K @ np.hstack([R2, t2[:, None]]), R=R2, t=t2)


def test_infer_refuses_a_camera_looking_away_before_detection(tmp_path, capsys):
    from inference.camera import Camera

    clip = _sample(tmp_path)
    _looking_away(Camera.load(clip / "gt" / "camera.yaml")).save(tmp_path / "away.yaml")
    code = main(["infer", str(clip), "--camera", str(tmp_path / "away.yaml"), "--out", str(tmp_path / "o"),
                 "--no-progress", "--pose", "none"])
    err = capsys.readouterr().err
    assert code == 1
    assert "away.yaml" in err and "behind" in err and "Traceback" not in err
    assert not (tmp_path / "o" / "ball.csv").exists()


def test_camera_stage_and_drift_survive_a_camera_looking_away(tmp_path, capsys):
    from inference.camera import Camera
    from inference.court import load_court
    from inference.courtfit.drift import measure_drift

    clip = _sample(tmp_path)
    away = _looking_away(Camera.load(clip / "gt" / "camera.yaml"))
    away.save(clip / "camera.yaml")  # put there by hand: the camera stage judges it
    report = measure_drift(Clip(clip), away, load_court("padel"))
    assert not report.valid.any()
    code = main(["infer", str(clip), "--no-progress", "--pose", "none", "--only", "camera"])
    out = capsys.readouterr()
    assert code == 1 and "cannot see the court" in out.out + out.err


def test_calibrate_refuses_collinear_clicks(tmp_path, capsys):
    """Every floor point clicked along one image line gives a degenerate camera (focal ~0 px): refused,
    nothing written, the good camera.yaml kept."""
    clip = _sample(tmp_path)
    shutil.copy(clip / "gt" / "camera.yaml", clip / "camera.yaml")
    mine = (clip / "camera.yaml").read_text()
    from inference.court import load_court

    court = load_court("padel")
    names = [n for n in court.point_names if abs(court.points[n][2]) < 1e-9]
    xs = np.linspace(0.2, 0.8, len(names))
    lines = ["name,x,y"] + [f"{n},{x:.6f},{0.3 + 0.4 * x:.6f}" for n, x in zip(names, xs)]
    (clip / "court_points.csv").write_text("\n".join(lines) + "\n")
    code = main(["calibrate", str(clip)])
    err = capsys.readouterr().err
    assert code == 1 and "Nothing written" in err and "focal length" in err
    assert (clip / "camera.yaml").read_text() == mine and not _backups(clip, "camera.yaml")


def _clicks_from(clip: Path, move) -> str:
    """court_points.csv with the true camera's projections of every court point in the picture, each
    (name, xy px) passed through ``move`` -> (name, xy px) or None."""
    from inference.camera import Camera
    from inference.court import load_court

    cam, court = Camera.load(clip / "gt" / "camera.yaml"), load_court("padel")
    w, h = cam.image_size
    rows = ["name,x,y"]
    for n in court.point_names:
        xy = cam.project(court.points[n][None])[0]
        moved = move(n, xy) if 0 <= xy[0] < w and 0 <= xy[1] < h else None
        if moved is not None and moved[0] in court.points:
            rows.append(f"{moved[0]},{moved[1][0] / w:.6f},{moved[1][1] / h:.6f}")
    return "\n".join(rows) + "\n"


def _swap(name: str, a: str, b: str) -> str:
    return name.replace(a, "\0").replace(b, a).replace("\0", b)


@pytest.mark.parametrize("kind, move, reason", [
    ("clustered", lambda n, xy: (n, np.array([640.0, 360.0]) + (xy - [640.0, 360.0]) * 0.01), "focal length"),
    ("mirrored left-right", lambda n, xy: (_swap(n, "left", "right"), xy), "mirrored"),
    ("mirrored near-far", lambda n, xy: (_swap(n, "near", "far"), xy), "mirrored"),
])
def test_calibrate_refuses_degenerate_clicks_and_keeps_the_camera(tmp_path, capsys, kind, move, reason):
    """Clicks bunched in a few pixels, or on the mirrored names (left/right or near/far swapped), give a
    camera that cannot be right: refused with the reason, nothing written, the good camera.yaml kept."""
    clip = _sample(tmp_path)
    shutil.copy(clip / "gt" / "camera.yaml", clip / "camera.yaml")
    mine = (clip / "camera.yaml").read_text()
    (clip / "court_points.csv").write_text(_clicks_from(clip, move))
    code = main(["calibrate", str(clip)])
    err = capsys.readouterr().err
    assert code == 1 and "Nothing written" in err and reason in err, (kind, err)
    assert (clip / "camera.yaml").read_text() == mine and not _backups(clip, "camera.yaml")


def test_check_judges_the_camera(tmp_path, capsys):
    """rally3d check reads camera.yaml and judges it: a focal length of 0.035 px (what collinear clicks
    gave before they were refused) fails with the reason; the true camera passes."""
    from inference.camera import Camera

    clip = _sample(tmp_path)
    good = Camera.load(clip / "gt" / "camera.yaml")
    good.save(clip / "camera.yaml")
    assert main(["check", str(clip)]) == 0
    K = good.K.copy()
    K[0, 0] = K[1, 1] = 0.035
    Camera.from_krt(K, good.R, good.t, good.image_size).save(clip / "camera.yaml")
    assert main(["check", str(clip)]) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "camera.yaml" in out and "focal length is 0.035 px" in out

