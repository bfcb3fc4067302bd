"""Label Studio video JSON <-> clip folder: the ball track and the events (docs/interchange.md).

Label Studio's JSON export is a list of tasks; each has ``annotations``, each a ``result`` list of
regions. The ball is a ``videorectangle`` region (or any region with a keypoint ``sequence``): keyframes
``{"frame", "enabled", "x", "y"[, "width", "height"], "time"}`` with 1-based frames, coordinates in percent
of the frame and ``time = frame / frame rate`` (as Label Studio's editor, converter and ML backend write
it). Events and visibility spans are ``timelinelabels`` regions: ``{"ranges": [{"start", "end"}],
"timelinelabels": [label]}``, 1-based, inclusive.
"""

from __future__ import annotations

import heapq
import json
import math
import reprlib
from itertools import pairwise
from pathlib import Path
from typing import Any

import numpy as np

from inference.clipio import BallTrack, FormatError, HitEvents
from inference.clipio.atomic import atomic_write_text
from inference.clipio.csvtable import read_text

from .common import (
    BALL,
    MAX_FRAMES,
    MAX_FRAMES_TEXT,
    MAX_IMAGE_SIDE,
    Imported,
    Key,
    LabelMap,
    Rows,
    RowTable,
    add_keyframe_track,
    check_frame,
    labelled_runs,
    make_events,
    runs,
    tighter,
)

VISIBILITY_LABELS: dict[str, int] = {"out_of_frame": 0, "hard_to_see": 2, "occluded": 3}
"""Timeline labels that set ball.csv's visibility on the frames they cover (default 1)."""

BOX_PX = 12.0
"""Side of the square box written around the ball on export (pixels); shrunk at the image edge."""

MAX_FPS = 1000.0
"""Highest frame rate a file may state (``data.fps``, ``framesCount / duration``)."""
RATE_TOLERANCE = 0.05
"""Keyframe times that imply a frame rate this far (relative) from the task's ``data.fps`` get a warning."""

TIMELINE_TYPES = ("timelinelabels",)
BOX_NAME, TIMELINE_NAME = "box", "events"
"""Control names of the labeling config in docs/interchange.md (the export's ``from_name``)."""


def _fail(path: Path, where: str, problem: str, fix: str) -> FormatError:
    return FormatError(path, f"{where}: {problem}", fix=fix)


def _short_repr() -> reprlib.Repr:
    short = reprlib.Repr()
    short.maxlevel, short.maxstring, short.maxother, short.maxlist, short.maxdict = 2, 40, 40, 4, 4
    return short


_REPR = _short_repr()


def _show(value: Any) -> str:
    """A short ``repr`` of any JSON value for a message (safe for deep or huge values)."""
    return _REPR.repr(value)


def _load(path: Path) -> Any:
    """The parsed JSON (:class:`FormatError` for anything that is not JSON Python can hold)."""
    text = read_text(path)
    fix = "export the project again from Label Studio as JSON"
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        problem = f"not valid JSON ({e.msg}, column {e.colno})"
        raise FormatError(path, problem, line=e.lineno, fix=fix) from None
    except RecursionError:
        raise FormatError(path, "not a Label Studio export: nested too deeply", fix=fix) from None
    except ValueError:  # an integer with more digits than Python converts (4300)
        problem = "not valid JSON for Python: a number with thousands of digits"
        raise FormatError(path, problem, fix=fix) from None


def _data(task: dict) -> dict:
    """The task's ``data`` (empty when it is not a mapping)."""
    return task["data"] if isinstance(task.get("data"), dict) else {}


def _video(task: dict) -> str:
    """The task's ``data.video`` as printable text (a lone surrogate of a JSON escape is spelt out)."""
    video = _data(task).get("video", "")
    text = video if isinstance(video, str) else _show(video)
    return text.encode("utf-8", "backslashreplace").decode("utf-8")


def _tasks(path: Path, data: Any) -> list[dict]:
    if isinstance(data, dict):
        data = [data]
    if not isinstance(data, list) or not all(isinstance(t, dict) for t in data):
        raise FormatError(
            path,
            "the JSON is not a list of tasks",
            fix="use Label Studio's 'JSON' export (not JSON-MIN, CSV or COCO)",
        )
    for i, task in enumerate(data):
        if not {"annotations", "predictions", "data"} & set(task):
            raise FormatError(
                path,
                f"item {i} is not a Label Studio task (no 'data', 'annotations' or 'predictions')",
                fix="use Label Studio's 'JSON' export (not JSON-MIN, CSV or COCO)",
            )
    return data


def _entries(path: Path, where: str, task: dict, key: str) -> list[dict]:
    """The task's ``annotations`` or ``predictions``: a list of objects (absent or null: none)."""
    value = task.get(key)
    if value is None:
        return []
    if not isinstance(value, list):
        raise _fail(
            path,
            where,
            f"{key!r} is {_show(value)}, not a list",
            fix="use Label Studio's 'JSON' export (not JSON-MIN, CSV or COCO)",
        )
    return [v for v in value if isinstance(v, dict)]


def _pick(path: Path, items: list[dict], wanted: int | None, what: str, fix: str) -> tuple[int, dict]:
    if wanted is not None:
        for i, item in enumerate(items):
            if item.get("id") == wanted:
                return i, item
        ids = ", ".join(_show(t.get("id")) for t in items)
        raise FormatError(path, f"no {what} with id {wanted} (ids: {ids})", fix=fix)
    return 0, items[0]


def _number(path: Path, where: str, item: dict, key: str, *, required: bool = True) -> float | None:
    value = item.get(key)
    if value is None and not required:
        return None
    number = math.nan  # not a number: text, true/false, a list, an int beyond a float's range
    if type(value) is float:
        number = value
    elif type(value) is int and abs(value) < 2**63:
        number = float(value)
    if not math.isfinite(number):
        raise _fail(path, where, f"{key!r} is {_show(value)}, not a number", fix=f"write {key} as a number")
    return number


def _frame(path: Path, where: str, item: dict, key: str, limit: tuple[int | None, str]) -> int:
    """``item[key]``, a 1-based frame, as a clip frame below ``limit`` ((frames, words); None: MAX_FRAMES)."""
    value = _number(path, where, item, key)
    if value != int(value) or value < 1:
        raise _fail(
            path,
            where,
            f"{key!r} is {value:g}, not a frame number >= 1",
            fix="Label Studio counts video frames from 1",
        )
    frame = int(value) - 1
    check_frame(path, frame, limit[0], where=where, shown=frame + 1, stated=limit[1])
    return frame


def _frames_count(path: Path, where: str, value: dict) -> int | None:
    """``value.framesCount`` (None when absent or not a whole number), at most :data:`MAX_FRAMES`."""
    count = value.get("framesCount")
    if isinstance(count, bool) or not isinstance(count, int) or count <= 0:
        return None
    if count > MAX_FRAMES:
        raise _fail(
            path,
            where,
            f"framesCount {count} is more than {MAX_FRAMES} frames ({MAX_FRAMES_TEXT})",
            fix="check the task's video; rally3d reads clips of at most " + MAX_FRAMES_TEXT,
        )
    return count


def _rate(value: Any) -> float | None:
    """``value`` as a frame rate in ``(0, MAX_FPS]``, else None."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and 0 < value <= MAX_FPS
    return float(value) if ok else None


def _labels(value: dict) -> list[str]:
    for key in ("labels", "timelinelabels", "videorectangle", "keypointlabels", "rectanglelabels"):
        if isinstance(value.get(key), list):
            return [v if isinstance(v, str) else _show(v) for v in value[key]]
    return []


def import_labelstudio(
    path: str | Path,
    labels: LabelMap | None = None,
    *,
    task: int | None = None,
    annotation: int | None = None,
    clip_frames: int | None = None,
) -> Imported:
    """Read one task of a Label Studio JSON export into a ball track and events.

    Args:
        path: the export (a list of tasks, or one task).
        labels: which labels are the ball and which are events; the timeline labels
            :data:`VISIBILITY_LABELS` set the ball's visibility.
        task: the task id, when the file holds several tasks.
        annotation: the annotation id, when the task has several (default: the first not cancelled).
        clip_frames: the length of the clip the labels go into, when known: frames must lie below it
            (checked, like ``framesCount``, before anything is built).

    Returns:
        :class:`~inference.interchange.common.Imported` (no image size: coordinates are percentages).
    """
    path = Path(path)
    labels = labels or LabelMap()
    tasks = _tasks(path, _load(path))
    if not tasks:
        raise FormatError(path, "the export holds no task", fix="export a project with annotated tasks")
    if len(tasks) > 1 and task is None:
        listing = "; ".join(f"{_show(t.get('id'))}: {_video(t)[-40:]}" for t in tasks[:10])
        raise FormatError(
            path,
            f"{len(tasks)} tasks in the file ({listing})",
            fix="choose one with --task ID (one task = one clip)",
        )
    ti, chosen = _pick(path, tasks, task, "task", "pass an id from the file")
    where_task = f"task {_show(chosen.get('id', ti))}"
    warnings: list[str] = []
    anns = _entries(path, where_task, chosen, "annotations")
    live = [a for a in anns if not a.get("was_cancelled")]
    if not live:
        preds = _entries(path, where_task, chosen, "predictions")
        if not preds:
            raise FormatError(
                path, f"{where_task} has no annotation", fix="annotate the task, or pick another"
            )
        live = preds
        warnings.append(f"{path}: {where_task} has no annotation; its prediction was read instead")
    if annotation is None and len(live) > 1:
        warnings.append(
            f"{path}: {where_task} has {len(live)} annotations; read the first "
            f"(id {_show(live[0].get('id'))}), choose another with --annotation ID"
        )
    ai, ann = _pick(path, live, annotation, "annotation", "pass an annotation id of the task")
    where_ann = f"{where_task}, annotation {_show(ann.get('id', ai))}"
    result = ann.get("result")
    if not isinstance(result, list):
        raise _fail(path, where_ann, "has no 'result' list", fix="export the project again as JSON")

    n_frames: int | None = None
    fps: float | None = None
    ball_regions, timeline = [], []
    skipped: dict[str, int] = {}
    for ri, region in enumerate(result):
        where = f"{where_ann}, result[{ri}]"
        if not isinstance(region, dict) or not isinstance(region.get("value"), dict):
            raise _fail(path, where, "is not a region with a 'value'", fix="export the project again as JSON")
        value = region["value"]
        names = _labels(value)
        if "sequence" in value:
            if (count := _frames_count(path, where, value)) is not None:
                n_frames = count
                duration = value.get("duration")
                if isinstance(duration, (int, float)) and not isinstance(duration, bool) and duration > 0:
                    fps = _rate(round(n_frames / duration, 3)) or fps
            name = names[0] if names else BALL
            kind = labels.kind(name)
            if kind == BALL:
                ball_regions.append((where, value["sequence"]))
            elif kind is None:
                skipped[name] = skipped.get(name, 0) + 1
            elif kind == "event":
                raise _fail(
                    path,
                    where,
                    f"a tracked box labelled with the event {name!r}",
                    fix="mark events on the timeline (TimelineLabels), or map the label with --label-map",
                )
        elif region.get("type") in TIMELINE_TYPES or "ranges" in value:
            timeline.append((where, value, names))
        else:
            skipped[str(region.get("type"))] = skipped.get(str(region.get("type")), 0) + 1

    rows = Rows(path)
    last_frame = n_frames - 1 if n_frames else None
    limit = tighter(n_frames, f"the video's {n_frames} frames (framesCount {n_frames})", clip_frames)
    times: list[tuple[str, float]] = []
    for where, sequence in ball_regions:
        items = _list(path, where, sequence)
        keys = [_key(path, f"{where}, sequence[{i}]", item, limit) for i, item in enumerate(items)]
        times += [(where, rate) for key, item in zip(keys, items) if (rate := _key_rate(key, item))]
        if add_keyframe_track(rows, keys, last_frame=last_frame, end_marker=False):
            warnings.append(
                f"{path}: {where}: the ball's last keyframe has interpolation on; rows stop there"
            )

    found: dict[int, list[tuple[str, str]]] = {}
    spans: list[tuple[str, int, int, int]] = []
    for where, value, names in timeline:
        for ri, (start, end) in enumerate(_ranges(path, where, value, limit)):
            where_r = f"{where}, ranges[{ri}]"
            for name in names:
                if name in VISIBILITY_LABELS:
                    spans.append((where_r, start, end, VISIBILITY_LABELS[name]))
                    continue
                kind = labels.kind(name)
                if kind == "event":
                    frame = (start + end) // 2
                    if end > start:
                        warnings.append(
                            f"{path}: {where_r}: event {name!r} spans frames {start}-{end}; put on "
                            f"frame {frame} (mark contacts as single frames)"
                        )
                    found.setdefault(frame, []).append((labels.events[name], where_r))
                elif kind is None:
                    skipped[name] = skipped.get(name, 0) + 1
                elif kind == BALL:
                    raise _fail(
                        path,
                        where_r,
                        f"the ball label {name!r} on the timeline",
                        fix="draw the ball with a box (VideoRectangle); use out_of_frame, hard_to_see or "
                        "occluded on the timeline",
                    )
    for name, count in sorted(skipped.items()):
        warnings.append(f"{path}: skipped {count} region(s) labelled {name!r}: " + labels.unknown_hint(name))
    _apply_visibility(rows, spans)
    ball = rows.track()
    events = make_events(path, found, n_frames)
    data = _data(chosen)
    video = _video(chosen)
    stated_fps = _stated_fps(path, where_task, data)
    if stated_fps is not None:
        fps = stated_fps  # the task's own frame rate (the labeling config's frameRate="$fps")
        warnings += _rate_warnings(path, times, stated_fps)
    source = f"Label Studio task {_show(chosen.get('id'))}" + (f" ({Path(video).name})" if video else "")
    width, height = _stated_size(path, where_task, chosen)
    return Imported(ball, events, width, height, n_frames, fps, source, warnings)


def _stated_fps(path: Path, where: str, data: dict) -> float | None:
    """The task's ``data.fps`` (None when absent or not a number; an error when not a frame rate)."""
    value = data.get("fps")
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    if _rate(value) is None:
        raise _fail(
            path,
            where,
            f"data.fps is {_show(value)}, not a frame rate (0 to {MAX_FPS:g})",
            fix="write the video's frame rate",
        )
    return float(value)


def _key_rate(key: Key, item: dict) -> float | None:
    """The frame rate a keyframe's ``time`` implies (Label Studio writes time = frame / frameRate)."""
    time = item.get("time")
    if isinstance(time, bool) or not isinstance(time, (int, float)) or not 0 < time < float("inf"):
        return None
    return (key.frame + 1) / time


def _rate_warnings(path: Path, times: list[tuple[str, float]], fps: float) -> list[str]:
    """A warning when keyframe times say Label Studio counted frames at another rate than ``fps``."""
    if not times:
        return []
    implied = float(np.median([rate for _, rate in times]))
    if abs(implied / fps - 1) <= RATE_TOLERANCE:
        return []
    return [
        f"{path}: {times[0][0]}: keyframe times give {implied:.4g} fps (Label Studio writes time = frame / "
        f"frameRate), the task states {fps:g} fps: the labeling config's frameRate is not the video's, so "
        'its frame numbers drift from the video\'s; set frameRate="$fps" on <Video> and check the boxes'
    ]


def _stated_size(path: Path, where: str, task: dict) -> tuple[int | None, int | None]:
    """The image size rally3d's export keeps in the task's ``meta`` (Label Studio itself states none)."""
    meta = task.get("meta") if isinstance(task.get("meta"), dict) else {}
    ours = meta.get("rally3d") if isinstance(meta.get("rally3d"), dict) else {}
    w, h = ours.get("width"), ours.get("height")
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (w, h)):
        return None, None
    if not all(0 < v <= MAX_IMAGE_SIDE for v in (w, h)):
        raise _fail(
            path,
            where,
            f"meta.rally3d states a {_show(w)}x{_show(h)} image",
            fix=f"write a width and height of 1 to {MAX_IMAGE_SIDE} pixels, or delete meta.rally3d",
        )
    return w, h


def _list(path: Path, where: str, value: Any) -> list[dict]:
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise _fail(
            path, where, "'sequence' is not a list of keyframes", fix="export the project again as JSON"
        )
    return value


def _key(path: Path, where: str, item: dict, limit: tuple[int | None, str]) -> Key:
    frame = _frame(path, where, item, "frame", limit)
    x, y = _number(path, where, item, "x"), _number(path, where, item, "y")
    w = _number(path, where, item, "width", required=False) or 0.0
    h = _number(path, where, item, "height", required=False) or 0.0
    u, v = (x + w / 2) / 100, (y + h / 2) / 100
    if not (-1e-3 <= u <= 1 + 1e-3 and -1e-3 <= v <= 1 + 1e-3):
        raise _fail(
            path,
            where,
            f"ball centre ({100 * u:.3g} %, {100 * v:.3g} %) lies outside the frame",
            fix="x, y, width, height are percentages (0-100) of the frame size",
        )
    enabled = item.get("enabled", True)
    if not isinstance(enabled, bool):
        raise _fail(path, where, f"'enabled' is {enabled!r}, not true/false", fix="write true or false")
    return Key(frame, (min(max(u, 0.0), 1.0), min(max(v, 0.0), 1.0)), 1, enabled, where)


def _ranges(path: Path, where: str, value: dict, limit: tuple[int | None, str]) -> list[tuple[int, int]]:
    ranges = value.get("ranges")
    if not isinstance(ranges, list) or not ranges:
        raise _fail(path, where, "timeline region without 'ranges'", fix="export the project again as JSON")
    out = []
    for i, r in enumerate(ranges):
        if not isinstance(r, dict):
            raise _fail(
                path, f"{where}, ranges[{i}]", "is not {start, end}", fix='write {"start": F, "end": F}'
            )
        start, end = (
            _frame(path, f"{where}, ranges[{i}]", r, "start", limit),
            _frame(path, f"{where}, ranges[{i}]", r, "end", limit),
        )
        if end < start:
            raise _fail(
                path,
                f"{where}, ranges[{i}]",
                f"ends (frame {end + 1}) before it starts ({start + 1})",
                fix="swap start and end",
            )
        out.append((start, end))
    return out


def _apply_visibility(rows: Rows, spans: list[tuple[str, int, int, int]]) -> None:
    """Apply the timeline's visibility spans ``(where, first, last clip frame, code)``, in file order.

    ``out_of_frame`` (0) adds hidden rows and may cover no box; ``hard_to_see``/``occluded`` (2/3) set the
    visibility of the boxes they cover and must cover only boxes; where those overlap, the later span wins.
    Each span is checked in O(log rows); painting and the hidden rows cost O(rows + spans log spans), so
    many long spans cost no more than the rows they make.
    """
    if not spans:
        return
    table = rows.table()
    boxed = np.r_[0, np.cumsum(table.visibility > 0)]  # boxes before each row
    bounds = np.searchsorted(table.frame, [(start, end + 1) for _, start, end, _ in spans])
    for (where, start, end, code), (lo, hi) in zip(spans, bounds.tolist()):
        n_boxed = int(boxed[hi] - boxed[lo])
        if code == 0 and n_boxed:
            i = lo + int(np.argmax(table.visibility[lo:hi] > 0))
            raise _fail(
                rows.path,
                where,
                f"frame {int(table.frame[i]) + 1} is out_of_frame but has a ball box "
                f"({rows.wheres[table.source[i]]})",
                fix="shorten the out_of_frame span or delete the box on that frame",
            )
        if code and n_boxed != end - start + 1:
            have = table.frame[lo:hi][table.visibility[lo:hi] > 0]
            gaps = np.flatnonzero(have != start + np.arange(len(have)))
            missing = start + (int(gaps[0]) if gaps.size else len(have))
            raise _fail(
                rows.path,
                where,
                f"frame {missing + 1} is marked {code} (hard to see/occluded) but has no ball box",
                fix="draw the box on that frame or shorten the span",
            )
    _paint(table, [(start, end, code, k) for k, (_, start, end, code) in enumerate(spans) if code])
    hidden = _union([(start, end, where) for where, start, end, code in spans if code == 0])
    if hidden:
        first = np.array([h[0] for h in hidden], np.int64)
        count = np.array([h[1] - h[0] + 1 for h in hidden], np.int64)
        n = int(count.sum())
        frames = np.repeat(first - (np.cumsum(count) - count), count) + np.arange(n)
        places = np.repeat(np.array([rows.source(h[2]) for h in hidden], np.int64), count)
        rows.add(frames, np.zeros(n), np.full((n, 2), np.nan), places)


def _paint(table: RowTable, marks: list[tuple[int, int, int, int]]) -> None:
    """Set ``table``'s visibility over spans ``(first, last frame, code, order)``; the latest order wins."""
    if not marks:
        return
    points = sorted({m[0] for m in marks} | {m[1] + 1 for m in marks})
    marks = sorted(marks)
    active: list[tuple[int, int, int]] = []  # (-order, last frame, code): the latest span on top
    j = 0
    for a, b in pairwise(points):
        while j < len(marks) and marks[j][0] <= a:
            heapq.heappush(active, (-marks[j][3], marks[j][1], marks[j][2]))
            j += 1
        while active and active[0][1] < a:
            heapq.heappop(active)
        if active:
            lo, hi = np.searchsorted(table.frame, [a, b])
            table.visibility[lo:hi] = active[0][2]


def _union(spans: list[tuple[int, int, str]]) -> list[tuple[int, int, str]]:
    """Overlapping or touching spans ``(first, last, where)`` joined (each keeps its first ``where``)."""
    out: list[tuple[int, int, str]] = []
    for start, end, where in sorted(spans, key=lambda s: (s[0], s[1])):
        if out and start <= out[-1][1] + 1:
            out[-1] = (out[-1][0], max(out[-1][1], end), out[-1][2])
        else:
            out.append((start, end, where))
    return out


# ---------------------------------------------------------------------------------------------- export
def _spans(frames: np.ndarray) -> list[tuple[int, int]]:
    """Consecutive runs of sorted ``frames`` as ``(first, last)``."""
    return [(int(frames[i[0]]), int(frames[i[-1]])) for i in runs(frames)]


def export_labelstudio(
    path: str | Path,
    track: BallTrack,
    events: HitEvents,
    *,
    width: int,
    height: int,
    n_frames: int,
    fps: float,
    video_url: str = "video.mp4",
    task_id: int = 1,
) -> Path:
    """Write a ball track and events as a Label Studio JSON export (one task, one annotation).

    The ball: one ``videorectangle`` region per run of consecutive labelled frames, a keyframe on every
    visible row (a ``BOX_PX`` square centred on the ball), ``enabled`` only where the next frame is a
    visible row of the same run. Visibility 0, 2 and 3 become ``out_of_frame``, ``hard_to_see`` and
    ``occluded`` timeline spans; each event a one-frame ``timelinelabels`` range. Frames are 1-based.
    """
    result: list[dict] = []
    xy = track.xy
    half_w, half_h = BOX_PX / 2 / width, BOX_PX / 2 / height
    for r, run in enumerate(labelled_runs(track)):
        visible = [i for i in run if track.visibility[i] > 0]
        if not visible:
            continue
        sequence = []
        for i in visible:
            u, v = xy[i]
            hw, hh = min(half_w, u, 1 - u), min(half_h, v, 1 - v)
            # a run holds consecutive frames, so the next row of the run is the next frame
            enabled = bool(i + 1 <= run[-1] and track.visibility[i + 1] > 0)
            sequence.append(
                {
                    "frame": int(track.frame[i]) + 1,
                    "enabled": enabled,
                    "rotation": 0,
                    "x": 100 * (u - hw),
                    "y": 100 * (v - hh),
                    "width": 200 * hw,
                    "height": 200 * hh,
                    "time": round((int(track.frame[i]) + 1) / fps, 6),  # Label Studio's frame / fps
                }
            )
        result.append(
            {
                "id": f"ball{r}",
                "type": "videorectangle",
                "from_name": BOX_NAME,
                "to_name": "video",
                "origin": "manual",
                "value": {
                    "framesCount": n_frames,
                    "duration": n_frames / fps,
                    "labels": [BALL],
                    "sequence": sequence,
                },
            }
        )
    for name, code in VISIBILITY_LABELS.items():
        spans = _spans(track.frame[track.visibility == code])
        if spans:
            result.append(
                {
                    "id": f"vis_{name}",
                    "type": "timelinelabels",
                    "from_name": TIMELINE_NAME,
                    "to_name": "video",
                    "origin": "manual",
                    "value": {
                        "ranges": [{"start": a + 1, "end": b + 1} for a, b in spans],
                        "timelinelabels": [name],
                    },
                }
            )
    for k, (frame, label) in enumerate(zip(events.frame.tolist(), events.event.tolist())):
        result.append(
            {
                "id": f"event{k}",
                "type": "timelinelabels",
                "from_name": TIMELINE_NAME,
                "to_name": "video",
                "origin": "manual",
                "value": {"ranges": [{"start": frame + 1, "end": frame + 1}], "timelinelabels": [label]},
            }
        )
    task = {
        "id": task_id,
        "data": {"video": video_url, "fps": fps},
        "annotations": [{"id": 1, "was_cancelled": False, "result": result}],
        "meta": {"rally3d": {"width": width, "height": height, "fps": fps}},
    }
    return atomic_write_text(path, json.dumps([task], indent=1) + "\n")
