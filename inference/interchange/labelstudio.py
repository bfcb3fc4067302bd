"""Label Studio video JSON <-> clip folder: the ball track and the events (docs/interchange.md).

Label Studio's JSON export is a list of tasks; each has ``annotations``, each a ``result`` list of
regions. The ball is a ``videorectangle`` region (or any region with a keypoint ``sequence``): keyframes
``{"frame", "enabled", "x", "y"[, "width", "height"]}`` with 1-based frames and coordinates in percent of
the frame. Events and visibility spans are ``timelinelabels`` regions: ``{"ranges": [{"start", "end"}],
"timelinelabels": [label]}``, 1-based, inclusive.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from inference.clipio import BallTrack, FormatError, HitEvents
from inference.clipio.atomic import atomic_write_text
from inference.clipio.csvtable import read_text

from .common import BALL, Imported, Key, LabelMap, Rows, add_keyframe_track, labelled_runs, make_events, runs

VISIBILITY_LABELS: dict[str, int] = {"out_of_frame": 0, "hard_to_see": 2, "occluded": 3}
"""Timeline labels that set ball.csv's visibility on the frames they cover (default 1)."""

BOX_PX = 12.0
"""Side of the square box written around the ball on export (pixels); shrunk at the image edge."""

TIMELINE_TYPES = ("timelinelabels",)
BOX_NAME, TIMELINE_NAME = "box", "events"
"""Control names of the labeling config in docs/interchange.md (the export's ``from_name``)."""


def _fail(path: Path, where: str, problem: str, fix: str) -> FormatError:
    return FormatError(path, f"{where}: {problem}", fix=fix)


def _load(path: Path) -> Any:
    text = read_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise FormatError(
            path,
            f"not valid JSON ({e.msg}, column {e.colno})",
            line=e.lineno,
            fix="export the project again from Label Studio as JSON",
        ) from None


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


def _pick(path: Path, items: list[dict], wanted: int | None, what: str, fix: str) -> tuple[int, dict]:
    if wanted is not None:
        for i, item in enumerate(items):
            if item.get("id") == wanted:
                return i, item
        ids = ", ".join(str(t.get("id")) for t in items)
        raise FormatError(path, f"no {what} with id {wanted} (ids: {ids})", fix=fix)
    return 0, items[0]


def _number(path: Path, where: str, item: dict, key: str, *, required: bool = True) -> float | None:
    value = item.get(key)
    if value is None and not required:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise _fail(path, where, f"{key!r} is {value!r}, not a number", fix=f"write {key} as a number")
    return float(value)


def _frame(path: Path, where: str, item: dict, key: str) -> int:
    value = _number(path, where, item, key)
    if value != int(value) or value < 1:
        raise _fail(
            path,
            where,
            f"{key!r} is {value:g}, not a frame number >= 1",
            fix="Label Studio counts video frames from 1",
        )
    return int(value) - 1


def _labels(value: dict) -> list[str]:
    for key in ("labels", "timelinelabels", "videorectangle", "keypointlabels", "rectanglelabels"):
        if isinstance(value.get(key), list):
            return [str(v) for v in value[key]]
    return []


def import_labelstudio(
    path: str | Path,
    labels: LabelMap | None = None,
    *,
    task: int | None = None,
    annotation: int | None = None,
) -> Imported:
    """Read one task of a Label Studio JSON export into a ball track and events.

    Args:
        path: the export (a list of tasks, or one task).
        labels: which labels are the ball and which are events; the timeline labels
            :data:`VISIBILITY_LABELS` set the ball's visibility.
        task: the task id, when the file holds several tasks.
        annotation: the annotation id, when the task has several (default: the first not cancelled).

    Returns:
        :class:`~inference.interchange.common.Imported` (no image size: coordinates are percentages).
    """
    path = Path(path)
    labels = labels or LabelMap()
    tasks = _tasks(path, _load(path))
    if not tasks:
        raise FormatError(path, "the export holds no task", fix="export a project with annotated tasks")
    if len(tasks) > 1 and task is None:
        listing = "; ".join(
            f"{t.get('id')}: {str((t.get('data') or {}).get('video', ''))[-40:]}" for t in tasks[:10]
        )
        raise FormatError(
            path,
            f"{len(tasks)} tasks in the file ({listing})",
            fix="choose one with --task ID (one task = one clip)",
        )
    ti, chosen = _pick(path, tasks, task, "task", "pass an id from the file")
    where_task = f"task {chosen.get('id', ti)}"
    warnings: list[str] = []
    anns = [a for a in (chosen.get("annotations") or []) if isinstance(a, dict)]
    live = [a for a in anns if not a.get("was_cancelled")]
    if not live:
        preds = [p for p in (chosen.get("predictions") or []) if isinstance(p, dict)]
        if not preds:
            raise FormatError(
                path, f"{where_task} has no annotation", fix="annotate the task, or pick another"
            )
        live = preds
        warnings.append(f"{path}: {where_task} has no annotation; its prediction was read instead")
    if annotation is None and len(live) > 1:
        warnings.append(
            f"{path}: {where_task} has {len(live)} annotations; read the first "
            f"(id {live[0].get('id')}), choose another with --annotation ID"
        )
    ai, ann = _pick(path, live, annotation, "annotation", "pass an annotation id of the task")
    where_ann = f"{where_task}, annotation {ann.get('id', ai)}"
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
            if isinstance(value.get("framesCount"), int) and value["framesCount"] > 0:
                n_frames = value["framesCount"]
                duration = value.get("duration")
                if isinstance(duration, (int, float)) and duration > 0:
                    fps = round(n_frames / duration, 3)
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
    for where, sequence in ball_regions:
        keys = [
            _key(path, f"{where}, sequence[{i}]", item) for i, item in enumerate(_list(path, where, sequence))
        ]
        if add_keyframe_track(rows, keys, last_frame=last_frame, end_marker=False):
            warnings.append(
                f"{path}: {where}: the ball's last keyframe has interpolation on; rows stop there"
            )

    found: dict[int, list[tuple[str, str]]] = {}
    for where, value, names in timeline:
        for ri, (start, end) in enumerate(_ranges(path, where, value)):
            where_r = f"{where}, ranges[{ri}]"
            for name in names:
                if name in VISIBILITY_LABELS:
                    _set_visibility(rows, where_r, range(start, end + 1), VISIBILITY_LABELS[name])
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
    ball = rows.track()
    events = make_events(path, found, n_frames)
    data = chosen.get("data") if isinstance(chosen.get("data"), dict) else {}
    video = str(data.get("video", ""))
    stated_fps = data.get("fps")
    if isinstance(stated_fps, (int, float)) and not isinstance(stated_fps, bool) and stated_fps > 0:
        fps = float(stated_fps)  # the task's own frame rate (the labeling config's frameRate="$fps")
    source = f"Label Studio task {chosen.get('id')}" + (f" ({Path(video).name})" if video else "")
    width, height = _stated_size(chosen)
    return Imported(ball, events, width, height, n_frames, fps, source, warnings)


def _stated_size(task: dict) -> tuple[int | None, int | None]:
    """The image size rally3d's export keeps in the task's ``meta`` (Label Studio itself states none)."""
    meta = task.get("meta") if isinstance(task.get("meta"), dict) else {}
    ours = meta.get("rally3d") if isinstance(meta.get("rally3d"), dict) else {}
    w, h = ours.get("width"), ours.get("height")
    ok = all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in (w, h))
    return (w, h) if ok else (None, None)


def _list(path: Path, where: str, value: Any) -> list[dict]:
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        raise _fail(
            path, where, "'sequence' is not a list of keyframes", fix="export the project again as JSON"
        )
    return value


def _key(path: Path, where: str, item: dict) -> Key:
    frame = _frame(path, where, item, "frame")
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


def _ranges(path: Path, where: str, value: dict) -> list[tuple[int, int]]:
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
            _frame(path, f"{where}, ranges[{i}]", r, "start"),
            _frame(path, f"{where}, ranges[{i}]", r, "end"),
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


def _set_visibility(rows: Rows, where: str, frames: range, visibility: int) -> None:
    for f in frames:
        old = rows.rows.get(f)
        if visibility == 0:
            if old is not None and old[0] > 0:
                raise _fail(
                    rows.path,
                    where,
                    f"frame {f + 1} is out_of_frame but has a ball box ({old[3]})",
                    fix="shorten the out_of_frame span or delete the box on that frame",
                )
            rows.rows[f] = (0, np.nan, np.nan, where)
        else:
            if old is None or old[0] == 0:
                raise _fail(
                    rows.path,
                    where,
                    f"frame {f + 1} is marked {visibility} (hard to see/occluded) but has no ball box",
                    fix="draw the box on that frame or shorten the span",
                )
            rows.rows[f] = (visibility, old[1], old[2], old[3])


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
                    "time": round(int(track.frame[i]) / fps, 6),
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
