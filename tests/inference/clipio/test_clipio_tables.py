"""Validators and helpers of the typed tables (inference.clipio.tables)."""

import numpy as np
import pytest

from inference.clipio import (
    EVENT_LABELS,
    Ball3D,
    BallTrack,
    CourtPoints,
    HitEvents,
    InactiveBalls,
)

NAN = np.nan


def track(**overrides):
    kwargs = dict(frame=[0, 2, 5], visibility=[1, 0, 3], xy=[[0.1, 0.2], [NAN, NAN], [0.9, 1.0]])
    kwargs.update(overrides)
    return BallTrack(**kwargs)


def test_ball_track_coerces_dtypes():
    t = track()
    assert t.frame.dtype == np.int64 and t.visibility.dtype == np.int8 and t.xy.dtype == np.float64
    assert len(t) == 3
    assert t.visible_mask.tolist() == [True, False, True]


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (dict(xy=[[0.1, 0.2, 0.3]] * 3), r"\(N, 2\)"),
        (dict(visibility=[1, 0]), r"\(3,\)"),
        (dict(frame=[[0, 1, 2]]), r"\(N,\)"),
        (dict(frame=[0, 2, 2]), "strictly increasing"),
        (dict(frame=[2, 1, 5]), "strictly increasing"),
        (dict(frame=[-1, 2, 5]), ">= 0"),
        (dict(frame=[0.5, 2, 5]), "integers"),
        (dict(visibility=[1, 0, 4]), "0..3"),
        (dict(xy=[[NAN, 0.2], [NAN, NAN], [0.9, 1.0]]), "finite where visibility > 0"),
        (dict(xy=[[0.1, 0.2], [0.5, 0.5], [0.9, 1.0]]), "NaN where visibility == 0"),
        (dict(xy=[[0.1, 0.2], [NAN, NAN], [0.9, 1.01]]), r"\[0, 1\]"),
        (dict(xy=[[-0.01, 0.2], [NAN, NAN], [0.9, 1.0]]), r"\[0, 1\]"),
        (dict(xy=[[np.inf, 0.2], [NAN, NAN], [0.9, 1.0]]), "finite|infinite"),
    ],
)
def test_ball_track_rejects(overrides, message):
    with pytest.raises(ValueError, match=message):
        track(**overrides)


def test_ball_track_clips_within_tolerance():
    t = track(xy=[[-5e-7, 0.2], [NAN, NAN], [0.9, 1 + 5e-7]])
    assert t.xy[0, 0] == 0.0 and t.xy[2, 1] == 1.0


def test_ball_track_pixels_round_trip():
    t = track()
    px = t.to_pixels(1280, 720)
    np.testing.assert_allclose(px[0], [128.0, 144.0])
    assert np.isnan(px[1]).all()
    assert BallTrack.from_pixels(t.frame, t.visibility, px, 1280, 720) == t


def test_ball_track_dense_separates_unlabelled_from_invisible():
    dense = track().dense(7)
    assert dense.labelled.tolist() == [True, False, True, False, False, True, False]
    assert dense.visibility.tolist() == [1, -1, 0, -1, -1, 3, -1]
    np.testing.assert_allclose(dense.xy[5], [0.9, 1.0])
    assert np.isnan(dense.xy[[1, 2, 3]]).all()
    assert track().dense(6).labelled[5]
    with pytest.raises(ValueError, match="5 frames"):
        track().dense(5)


def test_ball_track_at():
    t = track()
    vis, xy = t.at(5)
    assert vis == 3 and xy.tolist() == [0.9, 1.0]
    assert t.at(2)[0] == 0
    assert t.at(3) is None and t.at(99) is None


@pytest.mark.parametrize("cls", [BallTrack, InactiveBalls, HitEvents, Ball3D])
def test_empty(cls):
    empty = cls.empty()
    assert len(empty) == 0
    assert empty == cls.empty()


def test_equality_detects_difference():
    assert track() != track(visibility=[2, 0, 3])
    assert track() == track()


def test_inactive_balls():
    balls = InactiveBalls(frame=[0, 0, 3], ball_no=[0, 1, 0], xy=[[0.1, 0.1], [0.2, 0.2], [0.3, 0.3]])
    assert balls.ball_no.dtype == np.int64 and len(balls) == 3


@pytest.mark.parametrize(
    ("frame", "ball_no", "message"),
    [
        ([0, 0], [1, 1], "unique"),
        ([0, 0], [1, 0], "unique and sorted"),
        ([3, 0], [0, 0], "sorted"),
        ([0, 1], [0, -1], ">= 0"),
    ],
)
def test_inactive_balls_rejects(frame, ball_no, message):
    with pytest.raises(ValueError, match=message):
        InactiveBalls(frame=frame, ball_no=ball_no, xy=[[0.1, 0.1], [0.2, 0.2]])


def test_hit_events():
    events = HitEvents(frame=[3, 9], event=["player_near", "ground"])
    assert events.at(9) == "ground" and events.at(4) is None
    assert set(EVENT_LABELS) >= set(events.event.tolist())


@pytest.mark.parametrize(
    ("frame", "event", "message"),
    [
        ([3, 9], ["player_near", "bounce"], "unknown values.*bounce"),
        ([9, 3], ["ground", "ground"], "strictly increasing"),
        ([3], ["ground", "net"], r"\(1,\)"),
    ],
)
def test_hit_events_rejects(frame, event, message):
    with pytest.raises(ValueError, match=message):
        HitEvents(frame=frame, event=event)


def test_court_points_dict_round_trip():
    points = CourtPoints.from_dict({"a": (0.1, 0.2), "b": (0.3, 0.4)})
    assert points.names == ["a", "b"]
    assert points.as_dict() == {"a": (0.1, 0.2), "b": (0.3, 0.4)}
    assert len(CourtPoints.from_dict({})) == 0


@pytest.mark.parametrize(
    ("names", "xy", "message"),
    [
        (["a", "a"], [[0.1, 0.1], [0.2, 0.2]], "unique"),
        (["a", ""], [[0.1, 0.1], [0.2, 0.2]], "non-empty"),
        (["a", "b"], [[0.1, 0.1]], r"\(N, 2\)"),
        (["a"], [[0.1, 1.5]], r"\[0, 1\]"),
    ],
)
def test_court_points_rejects(names, xy, message):
    with pytest.raises(ValueError, match=message):
        CourtPoints(names, xy)


def ball3d(**overrides):
    kwargs = dict(
        frame=[0, 0, 1],
        xyz=[[1, 2, 0.5], [1, 2, 0.4], [1.1, 2.2, 0.6]],
        segment=[0, 0, 0],
        kind=["fitted", "gt", "fitted"],
    )
    kwargs.update(overrides)
    return Ball3D(**kwargs)


def test_ball_3d_defaults_sigma_to_nan():
    ball = ball3d()
    assert ball.sigma.shape == (3,) and np.isnan(ball.sigma).all()
    assert ball.extra == {}


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        (dict(kind=["fitted", "fitted", "fitted"]), r"\(frame, kind\)"),
        (dict(kind=["fitted", "gt", "guess"]), "unknown values"),
        (dict(xyz=[[1, 2, 0.5], [1, 2, NAN], [1, 2, 3]]), "finite"),
        (dict(xyz=[[1, 2], [1, 2], [1, 2]]), r"\(N, 3\)"),
        (dict(frame=[1, 0, 0]), "sorted"),
        (dict(sigma=[0.1, -0.1, NAN]), ">= 0"),
        (dict(extra={"score": [1.0, 2.0]}), r"\(3,\)"),
    ],
)
def test_ball_3d_rejects(overrides, message):
    with pytest.raises(ValueError, match=message):
        ball3d(**overrides)
