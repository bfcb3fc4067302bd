"""Readers and writers for the CSV files of a clip folder (docs/formats.md).

Readers validate everything and raise :class:`~inference.clipio.errors.FormatError` naming the file,
the line and the fix; rows may come in any order and are returned sorted. Columns a reader does not know
(a hand-added ``note``) are kept as text and written back after the known ones. With ``skipped=[]`` a
reader leaves bad rows out instead of failing (the labeler's "open anyway, skip bad rows"). Writers are atomic and
deterministic: header, then rows sorted by frame, normalised coordinates with 7 decimals and metres
with 5.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from .csvtable import CsvTable, closest, duplicated, format_floats, format_ints, parse_rows, write_csv
from .errors import FormatError
from .tables import BALL3D_KINDS, EVENT_LABELS, Ball3D, BallTrack, CourtLinePoints, CourtPoints, HitEvents, InactiveBalls

BALL_COLUMNS = ("frame", "visibility", "x", "y")
INACTIVE_BALLS_COLUMNS = ("frame", "ball_no", "x", "y")
EVENTS_COLUMNS = ("frame", "event")
COURT_POINTS_COLUMNS = ("name", "x", "y")
COURT_LINE_POINTS_COLUMNS = ("start", "end", "x", "y")
BALL_3D_COLUMNS = ("frame", "x_m", "y_m", "z_m", "segment", "kind", "sigma_m")

UNIT_DECIMALS = 7
METRE_DECIMALS = 5

VISIBILITY_FIX = "visibility is 0 not in frame, 1 visible, 2 hard to see, 3 occluded"


def _frames(table: CsvTable, n_frames: int | None, *, unique: bool = True) -> np.ndarray:
    frame = table.ints("frame")
    table.check_frames(frame, n_frames=n_frames, unique=unique)
    return frame


def _unit_xy(table: CsvTable, *, allow_empty: bool = False) -> np.ndarray:
    return np.stack(
        [table.floats("x", allow_empty=allow_empty), table.floats("y", allow_empty=allow_empty)], axis=1
    ).reshape(len(table), 2)


# ----------------------------------------------------------------------------------------- ball.csv
def read_ball_csv(
    path: str | Path, *, n_frames: int | None = None, skipped: list[FormatError] | None = None
) -> BallTrack:
    """Read ``ball.csv`` (``frame,visibility,x,y`` plus any extra columns, kept in ``extra``).

    Args:
        path: the file.
        n_frames: frames of the video, when known; rows at or beyond it are rejected.
        skipped: when a list is given, bad rows are left out (their errors appended) instead of failing.

    Returns:
        The track, sorted by frame. Visibility-0 rows may leave x,y empty or write 0,0; both give NaN.
    """
    table = CsvTable.read(path, BALL_COLUMNS, skipped=skipped)
    return parse_rows(table, lambda t: _parse_ball(t, n_frames), skipped)


def _parse_ball(table: CsvTable, n_frames: int | None) -> BallTrack:
    frame = _frames(table, n_frames)
    visibility = table.ints("visibility")
    table.check(
        (visibility < 0) | (visibility > 3),
        lambda i: f"visibility {visibility[i]} is not in 0..3",
        fix=VISIBILITY_FIX,
    )
    xy = _unit_xy(table, allow_empty=True)
    visible = visibility > 0
    table.check(
        visible & np.isnan(xy).any(axis=1),
        lambda i: f"visibility {visibility[i]} but x or y is empty",
        fix="write the ball centre, or set visibility 0 when the ball is not in the frame",
    )
    table.check(
        ~visible & (np.nan_to_num(xy) != 0).any(axis=1),
        "visibility 0 but x,y give a position",
        fix="set visibility 1-3 when the ball is in the frame, or leave x,y empty",
    )
    xy[~visible] = np.nan
    xy = table.unit_coords(xy, ("x", "y"))
    order = np.argsort(frame, kind="stable")
    return BallTrack(frame[order], visibility[order], xy[order], _extra(table, BALL_COLUMNS, order))


def write_ball_csv(path: str | Path, track: BallTrack) -> Path:
    """Write ``track`` to ``ball.csv`` atomically (x,y empty where visibility is 0; extra columns last)."""
    return _write_with_extra(
        path,
        BALL_COLUMNS,
        [
            format_ints(track.frame),
            format_ints(track.visibility),
            format_floats(track.xy[:, 0], UNIT_DECIMALS),
            format_floats(track.xy[:, 1], UNIT_DECIMALS),
        ],
        track.extra,
    )


def _extra(table: CsvTable, known, order: np.ndarray) -> dict[str, np.ndarray]:
    """The file's unknown columns (text), rows in ``order``."""
    return {c: np.asarray(v, dtype=str).reshape(-1)[order] for c, v in table.extra_columns(known).items()}


def _write_with_extra(path, header, columns, extra: dict[str, np.ndarray]) -> Path:
    return write_csv(path, [*header, *extra], [*columns, *(np.asarray(v, str).tolist() for v in extra.values())])


# ------------------------------------------------------------------------------- inactive_balls.csv
def read_inactive_balls_csv(
    path: str | Path, *, n_frames: int | None = None, skipped: list[FormatError] | None = None
) -> InactiveBalls:
    """Read ``inactive_balls.csv`` (``frame,ball_no,x,y``), sorted by ``(frame, ball_no)``."""
    table = CsvTable.read(path, INACTIVE_BALLS_COLUMNS, skipped=skipped)
    return parse_rows(table, lambda t: _parse_inactive(t, n_frames), skipped)


def _parse_inactive(table: CsvTable, n_frames: int | None) -> InactiveBalls:
    frame = _frames(table, n_frames, unique=False)
    ball_no = table.ints("ball_no")
    table.check(
        ball_no < 0, lambda i: f"negative ball_no {ball_no[i]}", fix="number still balls 0, 1, 2, ..."
    )
    table.check(
        duplicated(np.stack([frame, ball_no], axis=1)),
        lambda i: f"duplicate (frame, ball_no) = ({frame[i]}, {ball_no[i]})",
        fix="keep one row per ball and frame",
    )
    xy = table.unit_coords(_unit_xy(table), ("x", "y"))
    order = np.lexsort((ball_no, frame))
    return InactiveBalls(frame[order], ball_no[order], xy[order], _extra(table, INACTIVE_BALLS_COLUMNS, order))


def write_inactive_balls_csv(path: str | Path, balls: InactiveBalls) -> Path:
    """Write ``balls`` to ``inactive_balls.csv`` atomically."""
    return _write_with_extra(
        path,
        INACTIVE_BALLS_COLUMNS,
        [
            format_ints(balls.frame),
            format_ints(balls.ball_no),
            format_floats(balls.xy[:, 0], UNIT_DECIMALS),
            format_floats(balls.xy[:, 1], UNIT_DECIMALS),
        ],
        balls.extra,
    )


# --------------------------------------------------------------------------------------- events.csv
def read_events_csv(
    path: str | Path,
    *,
    n_frames: int | None = None,
    labels: Sequence[str] | None = None,
    skipped: list[FormatError] | None = None,
) -> HitEvents:
    """Read ``events.csv`` (``frame,event``).

    Events on one frame are kept: the later row moves to the next free frame (see
    :func:`separate_same_frame`), with a warning.

    Args:
        labels: the event labels allowed for the clip's court (its surfaces and the players); default: any
            label of ``EVENT_LABELS``. A tennis clip has no walls, so ``wall_left`` is an error there.
        skipped: when a list is given, bad rows are left out (their errors appended) instead of failing.
    """
    allowed = tuple(EVENT_LABELS if labels is None else labels)
    table = CsvTable.read(path, EVENTS_COLUMNS, skipped=skipped)
    return parse_rows(table, lambda t: _parse_events(t, n_frames, allowed, path), skipped)


def _parse_events(table: CsvTable, n_frames: int | None, allowed: tuple[str, ...], path) -> HitEvents:
    frame = _frames(table, n_frames, unique=False)
    event = table.choices("event", allowed)
    order = np.argsort(frame, kind="stable")
    try:
        frame, event, moved = separate_same_frame(frame[order], event[order], n_frames)
    except ValueError as e:  # more events than frames: no row to point at, the file as a whole is wrong
        raise FormatError(path, str(e), fix="one event a frame at most: remove the extra rows, or correct "
                          "n_frames in clip.yaml") from None
    if moved:
        warnings.warn(f"{path}: events on one frame moved to the next free frame: {'; '.join(moved[:5])}"
                      + (f" (+{len(moved) - 5} more)" if len(moved) > 5 else ""), stacklevel=3)
    return HitEvents(frame, event, _extra(table, EVENTS_COLUMNS, order))


def separate_same_frame(frame: np.ndarray, event: np.ndarray,
                        n_frames: int | None = None) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Give every event its own frame, keeping their order.

    Events are sorted by frame (stable: rows of one frame keep their order); an event on a frame already
    taken moves to the next free frame (a corner bounce: floor, then glass a frame later). When that runs
    past ``n_frames``, the events at the end move back instead.

    Returns:
        (frame (N,) strictly increasing, event (N,), one note per moved event).
    """
    order = np.argsort(frame, kind="stable")
    f = np.asarray(frame, np.int64)[order].copy()
    ev = np.asarray(event)[order]
    moved = []
    for i in range(1, len(f)):
        if f[i] <= f[i - 1]:
            moved.append(f"{ev[i]} {f[i]} → {f[i - 1] + 1}")
            f[i] = f[i - 1] + 1
    if n_frames is not None and len(f) and f[-1] >= n_frames:
        f[-1] = n_frames - 1
        for i in range(len(f) - 2, -1, -1):
            f[i] = min(f[i], f[i + 1] - 1)
        if f[0] < 0:
            raise ValueError(f"{len(f)} events do not fit in {n_frames} frames")
    return f, ev, moved


def write_events_csv(path: str | Path, events: HitEvents) -> Path:
    """Write ``events`` to ``events.csv`` atomically."""
    return _write_with_extra(path, EVENTS_COLUMNS, [format_ints(events.frame), events.event.tolist()], events.extra)


# --------------------------------------------------------------------------------- court_points.csv
def read_court_points_csv(
    path: str | Path,
    *,
    known_names: Iterable[str] | None = None,
    skipped: list[FormatError] | None = None,
) -> CourtPoints:
    """Read ``court_points.csv`` (``name,x,y``).

    Args:
        path: the file.
        known_names: the point names of the court YAML; other names are rejected (with the closest
            valid name as a hint). None accepts any name.
        skipped: when a list is given, bad rows are left out (their errors appended) instead of failing.
    """
    known = None if known_names is None else list(known_names)
    table = CsvTable.read(path, COURT_POINTS_COLUMNS, skipped=skipped)
    return parse_rows(table, lambda t: _parse_court_points(t, known), skipped)


def _parse_court_points(table: CsvTable, known: list[str] | None) -> CourtPoints:
    names = table.strings("name")
    table.check(
        np.array([not n for n in names], dtype=bool), "empty point name", fix="write the court point's name"
    )
    table.check(
        duplicated(np.array(names, dtype=str)),
        lambda i: f"duplicate point {names[i]!r}",
        fix="keep one row per court point",
    )
    if known is not None:
        _check_known_names(table, names, known)
    xy = table.unit_coords(_unit_xy(table), ("x", "y"))
    return CourtPoints(names, xy, _extra(table, COURT_POINTS_COLUMNS, np.arange(len(table))))


def _check_known_names(table: CsvTable, names: list[str], known: list[str]) -> None:
    known_set = set(known)

    def problem(i: int) -> str:
        hint = closest(names[i], known)
        return f"unknown court point {names[i]!r}" + (f" (did you mean {hint!r}?)" if hint else "")

    table.check(
        np.array([n not in known_set for n in names], dtype=bool),
        problem,
        fix=f"use a point name of the court YAML: {', '.join(known)}",
    )


def write_court_points_csv(path: str | Path, points: CourtPoints) -> Path:
    """Write ``points`` to ``court_points.csv`` atomically, in their order."""
    return _write_with_extra(
        path,
        COURT_POINTS_COLUMNS,
        [
            points.names,
            format_floats(points.xy[:, 0], UNIT_DECIMALS),
            format_floats(points.xy[:, 1], UNIT_DECIMALS),
        ],
        points.extra,
    )


# ---------------------------------------------------------------------------- court_line_points.csv
def read_court_line_points_csv(path: str | Path, *, known_names: Iterable[str] | None = None,
                               skipped: list[FormatError] | None = None) -> CourtLinePoints:
    """Read ``court_line_points.csv`` (``start,end,x,y``: a pixel anywhere on the straight court line from the
    court point ``start`` to ``end``, normalised); with ``known_names`` other point names are rejected."""
    known = None if known_names is None else list(known_names)
    table = CsvTable.read(path, COURT_LINE_POINTS_COLUMNS, skipped=skipped)

    def parse(t: CsvTable) -> CourtLinePoints:
        start, end = t.strings("start"), t.strings("end")
        t.check(np.array([a == b for a, b in zip(start, end)], dtype=bool),
                lambda i: f"the line from {start[i]!r} to itself", fix="name the two court points at its ends")
        if known is not None:
            _check_known_names(t, start, known)
            _check_known_names(t, end, known)
        return CourtLinePoints(start, end, t.unit_coords(_unit_xy(t), ("x", "y")))

    return parse_rows(table, parse, skipped)


# -------------------------------------------------------------------------------------- ball_3d.csv
def read_ball_3d_csv(path: str | Path, *, n_frames: int | None = None) -> Ball3D:
    """Read ``ball_3d.csv`` (``frame,x_m,y_m,z_m,segment,kind[,sigma_m]`` plus any extra columns).

    Extra columns are kept as text in :attr:`Ball3D.extra` and written back unchanged.
    """
    table = CsvTable.read(path, BALL_3D_COLUMNS[:-1], optional=BALL_3D_COLUMNS[-1:])
    frame = _frames(table, n_frames, unique=False)
    kind = table.choices("kind", BALL3D_KINDS)
    table.check(
        duplicated(np.stack([frame, np.searchsorted(np.sort(BALL3D_KINDS), kind)], axis=1)),
        lambda i: f"duplicate (frame, kind) = ({frame[i]}, {kind[i]})",
        fix="keep one row per frame and kind",
    )
    xyz = np.stack([table.floats(c) for c in ("x_m", "y_m", "z_m")], axis=1).reshape(len(table), 3)
    segment = table.ints("segment")
    sigma = table.floats("sigma_m", allow_empty=True) if table.has("sigma_m") else np.full(len(table), np.nan)
    table.check(
        sigma < 0, lambda i: f"negative sigma_m {sigma[i]}", fix="sigma_m is a standard deviation >= 0"
    )
    extra = {c: np.array(table.strings(c), dtype=str) for c in table.header if c not in BALL_3D_COLUMNS}
    order = np.argsort(frame, kind="stable")
    return Ball3D(
        frame[order],
        xyz[order],
        segment[order],
        kind[order],
        sigma[order],
        {c: v[order] for c, v in extra.items()},
    )


def write_ball_3d_csv(path: str | Path, ball: Ball3D) -> Path:
    """Write ``ball`` to ``ball_3d.csv`` atomically, extra columns last."""
    columns = [
        format_ints(ball.frame),
        *(format_floats(ball.xyz[:, j], METRE_DECIMALS) for j in range(3)),
        format_ints(ball.segment),
        ball.kind.tolist(),
        format_floats(ball.sigma, METRE_DECIMALS),
        *(_format_any(v) for v in ball.extra.values()),
    ]
    return write_csv(path, [*BALL_3D_COLUMNS, *ball.extra], columns)


def _format_any(values: np.ndarray) -> list[str]:
    if values.dtype.kind == "f":
        return ["" if v != v else repr(v) for v in values.tolist()]
    return [str(v) for v in values.tolist()]
