"""players.csv: round trip with and without 3D joints, validation errors with file and line."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio import FormatError, PlayerTracks, read_players_csv, write_players_csv
from inference.clipio.players import BASE_COLUMNS, KP_COLUMNS

rng = np.random.default_rng(0)


def tracks(n_frames=5, n_players=2, with_3d=True) -> PlayerTracks:
    n = n_frames * n_players
    kp = rng.uniform(-0.1, 1.1, (n, 17, 3))
    kp[:, :, 2] = rng.uniform(0, 1, (n, 17))
    kp[3, 4] = np.nan  # a missing joint
    return PlayerTracks(
        frame=np.repeat(np.arange(n_frames), n_players),
        player_id=np.tile(np.arange(n_players), n_frames),
        team=["near", "far"] * n_frames,
        score=rng.uniform(0, 1, n),
        bbox=rng.uniform(0, 1, (n, 4)),
        keypoints=kp,
        court_xy=rng.uniform(0, 10, (n, 2)),
        joints_3d=rng.uniform(0, 2, (n, 17, 3)) if with_3d else None,
    )


@pytest.mark.parametrize("with_3d", [True, False])
def test_round_trip(tmp_path, with_3d):
    t = tracks(with_3d=with_3d)
    path = write_players_csv(tmp_path / "players.csv", t)
    back = read_players_csv(path)
    assert back.has_3d == with_3d
    np.testing.assert_allclose(back.keypoints, t.keypoints, atol=1e-4)
    np.testing.assert_allclose(back.court_xy, t.court_xy, atol=1e-5)
    assert back.team.tolist() == t.team.tolist()
    if with_3d:
        np.testing.assert_allclose(back.joints_3d, t.joints_3d, atol=1e-5)
    assert back.of_player(1).frame.tolist() == [0, 1, 2, 3, 4]


def test_empty_round_trip(tmp_path):
    back = read_players_csv(write_players_csv(tmp_path / "players.csv", PlayerTracks.empty()))
    assert len(back) == 0


def row(**over) -> str:
    vals = {c: "0.5" for c in BASE_COLUMNS + KP_COLUMNS}
    vals.update(frame="0", player_id="0", team="near")
    vals.update(over)
    return ",".join(vals[c] for c in BASE_COLUMNS + KP_COLUMNS)


HEADER = ",".join(BASE_COLUMNS + KP_COLUMNS)


@pytest.mark.parametrize(
    "rows, line, words",
    [
        ([row(), row(frame="1", team="middle")], 3, "unknown team 'middle'"),
        ([row(), row()], 3, "duplicate (frame, player_id)"),
        ([row(player_id="-2")], 2, "negative player_id"),
        ([row(nose_x="abc")], 2, "not a number"),
        ([row(frame="70")], 2, "beyond the video"),
    ],
)
def test_malformed(tmp_path, rows, line, words):
    path = tmp_path / "players.csv"
    path.write_text(HEADER + "\n" + "\n".join(rows) + "\n")
    with pytest.raises(FormatError) as e:
        read_players_csv(path, n_frames=50)
    assert f"players.csv, line {line}" in str(e.value) and words in str(e.value)


def test_missing_keypoint_columns_are_unknown_with_a_warning(tmp_path):
    path = tmp_path / "players.csv"
    path.write_text(",".join(BASE_COLUMNS) + "\n" + ",".join(["3", "1", "far", "0.9"] + ["0.5"] * 4 + ["4", "15"]) + "\n")
    with pytest.warns(UserWarning, match="51 keypoint columns"):
        t = read_players_csv(path)
    assert t.court_xy.tolist() == [[4.0, 15.0]] and t.team.tolist() == ["far"]
    assert np.isnan(t.keypoints).all()


def test_foreign_tracker_layout(tmp_path):
    """Another tracker's ``frame,track_id,team,x_m,y_m`` (teams A/B): read for what it has, one warning."""
    path = tmp_path / "players.csv"
    path.write_text("frame,track_id,team,x_m,y_m\n0,7,A,5.0,1.5\n0,9,B,4.0,18.0\n1,7,A,5.1,1.6\n")
    with pytest.warns(UserWarning) as rec:
        t = read_players_csv(path, n_frames=10)
    msg = str(rec[0].message)
    assert len(rec) == 1 and "another layout" in msg and "x1" in msg and "['A', 'B']" in msg
    assert t.player_id.tolist() == [7, 9, 7] and t.team.tolist() == ["", "", ""]
    np.testing.assert_allclose(t.court_xy, [[5.0, 1.5], [4.0, 18.0], [5.1, 1.6]])
    assert np.isnan(t.bbox).all() and np.isnan(t.score).all()


def test_foreign_layout_still_refuses_what_is_wrong(tmp_path):
    path = tmp_path / "players.csv"
    path.write_text("frame,track_id,x_m,y_m\n0,7,5.0,abc\n")
    with pytest.raises(FormatError, match="line 2.*not a number"):
        read_players_csv(path)
    path.write_text("track_id,x_m,y_m\n7,5.0,1.0\n")
    with pytest.raises(FormatError, match="missing column.*frame"):
        read_players_csv(path)
