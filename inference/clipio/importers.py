"""Importers for outside annotation formats (docs/formats.md, "Outside formats").

Each returns the typed objects of :mod:`.tables` and raises :class:`FormatError` naming the file and
line of bad input. Column names are matched case-insensitively.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from .csvtable import CsvTable, format_floats, format_ints, write_csv
from .errors import FormatError
from .tables import EVENT_LABELS, UNIT_TOLERANCE, BallTrack, CourtPoints, HitEvents

HitLabel = Callable[[int, float, float], str]
"""``(frame, u, v) -> event label`` for a TrackNet "hit"; ``u, v`` normalised, NaN when not visible."""

TRACKNET_COLUMNS = ("file name", "visibility", "x-coordinate", "y-coordinate")
TRACKNET_STATUS = {0: None, 1: "hit", 2: "bounce"}

PADEL_6CLASS_CODES: dict[int, str | None] = {
    0: None,
    1: "wall_near",
    2: "ground",  # the group ground_or_other_wall; reconstruction resolves the plane
    3: "player_near",
    4: "player_far",
    5: "net",
}
"""Class codes of the published padel hits CSV (``Frame,Hit``); None means "no event"."""


def hit_by_image_half(frame: int, u: float, v: float) -> str:
    """Default TrackNet hit label: ``player_near`` if the ball is in the lower half (v > 0.5).

    The near player stands at the bottom of the image; at the moment of a hit the ball is close to
    the hitter, so the image half is a good guess. Raises ``ValueError`` when the ball is not visible.
    """
    if np.isnan(v):
        raise ValueError("the ball is not visible, so the hitting side is unknown")
    return "player_near" if v > 0.5 else "player_far"


def _pixels_to_unit(
    table: CsvTable, xy_px: np.ndarray, columns: tuple[str, str], width: int, height: int
) -> np.ndarray:
    if width <= 0 or height <= 0:
        raise ValueError(f"width and height must be > 0, got {width}x{height}")
    xy = xy_px / np.array([width, height], dtype=np.float64)
    return table.unit_coords(
        xy,
        columns,
        fix=f"pixel coordinates must lie inside the {width}x{height} image; check width and height",
    )


def _sorted_track(table: CsvTable, frame: np.ndarray, visibility: np.ndarray, xy: np.ndarray) -> BallTrack:
    table.check_frames(frame)
    xy = np.where((visibility > 0)[:, None], xy, np.nan)
    order = np.argsort(frame, kind="stable")
    return BallTrack(frame[order], visibility[order], xy[order])


# ---------------------------------------------------------------------------------- TrackNet tennis
def import_tracknet_label(
    path: str | Path, width: int, height: int, *, hit_label: HitLabel = hit_by_image_half
) -> tuple[BallTrack, HitEvents]:
    """Read a TrackNet tennis ``Label.csv`` (``file name,visibility,x-coordinate,y-coordinate,status``).

    Args:
        path: the CSV (pixels; coordinates empty when visibility is 0).
        width, height: image size in pixels of the clip.
        hit_label: turns a "hit" (status 1) into ``player_near``/``player_far``; the default uses
            the image half (:func:`hit_by_image_half`). Bounces (status 2) become ``ground``.

    Returns:
        ``(track, events)``; the frame index is the number in the file name (``0042.jpg`` -> 42).
    """
    table = CsvTable.read(path, TRACKNET_COLUMNS, optional=("status",), ignore_case=True)
    frame = _frame_numbers(table, "file name")
    visibility = table.ints("visibility")
    table.check(
        (visibility < 0) | (visibility > 3),
        lambda i: f"visibility {visibility[i]} is not in 0..3",
        fix="TrackNet visibility is 0 (not in frame) to 3 (occluded)",
    )
    xy_px = np.stack([table.floats(c, allow_empty=True) for c in TRACKNET_COLUMNS[2:]], axis=1).reshape(-1, 2)
    table.check(
        (visibility > 0) & np.isnan(xy_px).any(axis=1),
        "visible ball without coordinates",
        fix="write x-coordinate,y-coordinate or set visibility 0",
    )
    xy_px[visibility == 0] = np.nan  # whatever an invisible row holds
    xy = _pixels_to_unit(table, xy_px, TRACKNET_COLUMNS[2:], width, height)
    track = _sorted_track(table, frame, visibility, xy)
    events = _tracknet_events(table, frame, xy, hit_label) if table.has("status") else HitEvents.empty()
    return track, events


def _frame_numbers(table: CsvTable, column: str) -> np.ndarray:
    names = table.strings(column)
    digits = [re.findall(r"\d+", Path(name).stem) for name in names]
    table.check(
        np.array([not d for d in digits], dtype=bool),
        lambda i: f"no frame number in {names[i]!r}",
        fix="file names must contain the frame index, e.g. 0000.jpg",
    )
    return np.array([int(d[-1]) for d in digits], dtype=np.int64)


def _tracknet_events(table: CsvTable, frame: np.ndarray, xy: np.ndarray, hit_label: HitLabel) -> HitEvents:
    status = table.ints("status")
    table.check(
        ~np.isin(status, list(TRACKNET_STATUS)),
        lambda i: f"status {status[i]} is not 0, 1 or 2",
        fix="TrackNet status is 0 flying, 1 hit, 2 bounce",
    )
    rows = np.flatnonzero(status > 0)
    labels = []
    for i in rows:
        if status[i] == 2:
            labels.append("ground")
            continue
        try:
            label = hit_label(int(frame[i]), float(xy[i, 0]), float(xy[i, 1]))
        except ValueError as err:
            raise table.error(
                int(i),
                f"cannot label the hit: {err}",
                fix="pass hit_label=... that handles this row, or mark the ball visible",
            ) from None
        if label not in EVENT_LABELS:
            raise table.error(
                int(i), f"hit_label returned {label!r}", fix=f"return one of {', '.join(EVENT_LABELS)}"
            )
        labels.append(label)
    order = np.argsort(frame[rows], kind="stable")
    return HitEvents(frame[rows][order], np.array(labels, dtype=str)[order] if labels else np.empty(0, "<U1"))


def export_tracknet_label(
    path: str | Path, track: BallTrack, events: HitEvents, width: int, height: int
) -> Path:
    """Write ``track`` and ``events`` as a TrackNet ``Label.csv`` (pixels, 2 decimals).

    ``player_*`` events become status 1 (hit), every other event status 2 (bounce). Every event
    frame must have a row in ``track``.
    """
    missing = np.setdiff1d(events.frame, track.frame)
    if missing.size:
        raise ValueError(f"events at frames without a ball row: {missing[:10].tolist()}")
    status = np.zeros(len(track), dtype=np.int64)
    rows = np.searchsorted(track.frame, events.frame)
    status[rows] = np.where(np.char.startswith(events.event.astype(str), "player_"), 1, 2)
    xy_px = track.to_pixels(width, height)
    return write_csv(
        path,
        ("file name", "visibility", "x-coordinate", "y-coordinate", "status"),
        [
            [f"{f:04d}.jpg" for f in track.frame.tolist()],
            format_ints(track.visibility),
            format_floats(xy_px[:, 0], 2),
            format_floats(xy_px[:, 1], 2),
            format_ints(status),
        ],
    )


# -------------------------------------------------------------------------- TrackNetV2/V3 badminton
def import_tracknet_badminton(path: str | Path, width: int, height: int) -> BallTrack:
    """Read a TrackNetV2/V3 badminton ``*_ball.csv`` (``Frame,Visibility,X,Y``, pixels).

    Invisible rows are written ``0,0,0``; their coordinates become NaN.
    """
    table = CsvTable.read(path, ("Frame", "Visibility", "X", "Y"), ignore_case=True)
    frame = table.ints("Frame")
    visibility = table.ints("Visibility")
    table.check(
        (visibility < 0) | (visibility > 1),
        lambda i: f"Visibility {visibility[i]} is not 0 or 1",
        fix="Visibility is 1 when the shuttle is in the frame, else 0",
    )
    xy_px = np.stack([table.floats("X", allow_empty=True), table.floats("Y", allow_empty=True)], axis=1)
    table.check(
        (visibility > 0) & np.isnan(xy_px).any(axis=1),
        "visible shuttle without X,Y",
        fix="write X,Y or set Visibility 0",
    )
    xy = _pixels_to_unit(
        table, np.where((visibility > 0)[:, None], xy_px, np.nan).reshape(-1, 2), ("X", "Y"), width, height
    )
    return _sorted_track(table, frame, visibility, xy)


# ------------------------------------------------------------------------------------ thesis layout
def _wide_points(
    path: str | Path, axes: tuple[str, ...], name_map: Mapping[str, str] | None, *, other_axes_fix: str = ""
) -> tuple[CsvTable, dict[str, np.ndarray]]:
    """Parse a one-row CSV with ``<POINT>_X, <POINT>_Y[, <POINT>_Z]`` columns.

    Returns the table and ``{mapped name: values (len(axes),)}`` (NaN where empty).
    """
    table = CsvTable.read(path, (), allow_empty=False)
    if len(table) != 1:
        raise table.error(1, f"{len(table)} data rows, expected one", fix="keep one row of point coordinates")
    groups: dict[str, dict[str, str]] = {}
    for column in table.header:
        m = re.fullmatch(r"(.+)_([XYZ])", column, flags=re.IGNORECASE)
        if not m:
            raise FormatError(
                table.path,
                f"column {column!r} is not <POINT>_X, <POINT>_Y or <POINT>_Z",
                line=1,
                fix="name the columns like NEAR_LEFT_X,NEAR_LEFT_Y",
            )
        groups.setdefault(m.group(1), {})[m.group(2).upper()] = column
    points: dict[str, np.ndarray] = {}
    for point, group in groups.items():
        if set(group) != set(axes):
            fix = (
                other_axes_fix
                if set(group) - set(axes) and other_axes_fix
                else f"give every point the columns {', '.join(f'{point}_{a}' for a in axes)}"
            )
            raise FormatError(
                table.path,
                f"point {point!r} has columns {sorted(group)}, expected {list(axes)}",
                line=1,
                fix=fix,
            )
        name = (name_map or {}).get(point, point)
        if name in points:
            raise FormatError(table.path, f"two points map to {name!r}", line=1, fix="check name_map")
        points[name] = np.array([table.floats(group[a], allow_empty=True)[0] for a in axes])
    return table, points


def import_thesis_court_points(
    path: str | Path,
    *,
    width: int | None = None,
    height: int | None = None,
    name_map: Mapping[str, str] | None = None,
) -> CourtPoints:
    """Read a wide court-point CSV of image positions (one row, ``<POINT>_X,<POINT>_Y`` columns).

    Values all ``<= 1`` are normalised; if any is ``> 1`` they are pixels and ``width``/``height``
    are required. Points with empty cells are not visible and left out. A file with ``_Z`` columns
    holds 3D court coordinates: read it with :func:`import_thesis_court_3d`.

    Args:
        path: the CSV.
        width, height: image size, for pixel files.
        name_map: renames points (``{thesis name: court YAML name}``); unmapped names are kept.
    """
    table, points = _wide_points(
        path,
        ("X", "Y"),
        name_map,
        other_axes_fix="_Z columns hold 3D court coordinates: use import_thesis_court_3d",
    )
    partial = [name for name, xy in points.items() if np.isnan(xy).sum() == 1]
    if partial:
        raise table.error(
            0, f"point {partial[0]!r} has only one coordinate", fix="fill both _X and _Y or neither"
        )
    visible = {name: xy for name, xy in points.items() if not np.isnan(xy).any()}
    xy = np.array(list(visible.values()), dtype=np.float64).reshape(-1, 2)
    if xy.size and xy.max() > 1:
        if not width or not height:
            raise table.error(
                0,
                "coordinates > 1 are pixels, but no image size was given",
                fix="pass width= and height= of the video",
            )
        xy = xy / np.array([width, height], dtype=np.float64)
    if xy.size and (xy.min() < 0 or xy.max() > 1 + UNIT_TOLERANCE):
        raise table.error(
            0, "coordinates outside the image", fix="check width/height and the point positions"
        )
    return CourtPoints(list(visible), np.clip(xy, 0.0, 1.0))


def import_thesis_court_3d(
    path: str | Path, *, name_map: Mapping[str, str] | None = None
) -> dict[str, tuple[float, float, float]]:
    """Read a wide court-model CSV (one row, ``<POINT>_X,<POINT>_Y,<POINT>_Z`` in metres).

    Returns ``{name: (x, y, z)}`` with names renamed by ``name_map``; every cell must be filled.
    """
    table, points = _wide_points(path, ("X", "Y", "Z"), name_map)
    for name, xyz in points.items():
        if np.isnan(xyz).any():
            raise table.error(
                0, f"point {name!r} has an empty coordinate", fix="fill _X, _Y and _Z of every point"
            )
    return {name: (float(x), float(y), float(z)) for name, (x, y, z) in points.items()}


def import_thesis_ball(path: str | Path, *, n_frames: int | None = None) -> BallTrack:
    """Read a thesis ball CSV (``Frame,Ball,x,y``, normalised; ``Ball`` 1 visible, 0 not in frame)."""
    table = CsvTable.read(path, ("Frame", "Ball", "x", "y"), ignore_case=True)
    frame = table.ints("Frame")
    table.check_frames(frame, n_frames=n_frames, column="Frame")
    ball = table.ints("Ball")
    table.check(
        (ball < 0) | (ball > 1),
        lambda i: f"Ball {ball[i]} is not 0 or 1",
        fix="Ball is 1 when visible, else 0",
    )
    xy = np.stack([table.floats("x", allow_empty=True), table.floats("y", allow_empty=True)], axis=1).reshape(
        -1, 2
    )
    table.check(
        (ball > 0) & np.isnan(xy).any(axis=1), "visible ball without x,y", fix="write x,y or set Ball 0"
    )
    xy = table.unit_coords(np.where((ball > 0)[:, None], xy, np.nan), ("x", "y"))
    return _sorted_track(table, frame, ball, xy)


def import_thesis_hits(
    path: str | Path,
    *,
    code_map: Mapping[int, str | None] = PADEL_6CLASS_CODES,
    n_frames: int | None = None,
) -> HitEvents:
    """Read a thesis hits CSV (``Frame,Hit``, integer class codes) into events.

    Args:
        path: the CSV.
        code_map: class code -> event label (None = no event); default :data:`PADEL_6CLASS_CODES`.
        n_frames: frames of the video, when known.
    """
    bad_labels = {c: v for c, v in code_map.items() if v is not None and v not in EVENT_LABELS}
    if bad_labels:
        raise ValueError(f"code_map has unknown event labels {bad_labels}; valid: {', '.join(EVENT_LABELS)}")
    table = CsvTable.read(path, ("Frame", "Hit"), ignore_case=True)
    frame = table.ints("Frame")
    table.check_frames(frame, n_frames=n_frames, column="Frame")
    code = table.ints("Hit")
    valid = ", ".join(f"{c} {v or 'none'}" for c, v in code_map.items())
    table.check(
        ~np.isin(code, list(code_map)), lambda i: f"unknown Hit code {code[i]}", fix=f"codes are: {valid}"
    )
    labels = (
        np.array([code_map[c] or "" for c in code.tolist()], dtype=str) if len(code) else np.empty(0, "<U1")
    )
    keep = labels != ""
    order = np.argsort(frame[keep], kind="stable")
    return HitEvents(frame[keep][order], labels[keep][order])
