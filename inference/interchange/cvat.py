"""CVAT for video 1.1 (XML) <-> clip folder: the ball track and the events (docs/interchange.md).

A CVAT task in interpolation mode holds ``<track label=...>`` elements of per-frame shapes with
``frame``, ``outside``, ``occluded`` and ``keyframe``. The ball is a ``points`` (or ``ellipse``, or
``box``) track in pixels of ``original_size`` (inside ``<meta><task>`` in a task export, in ``<meta>``
after ``</job>`` in a job export); events are tracks (or shapes) whose label is an event label, or
root-level ``<tag frame label>`` elements.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from inference.clipio import EVENT_LABELS, BallTrack, FormatError, HitEvents
from inference.clipio.atomic import atomic_write_text

from .common import (
    BALL,
    MAX_FRAMES,
    MAX_FRAMES_TEXT,
    MAX_IMAGE_SIDE,
    Imported,
    Key,
    LabelMap,
    Rows,
    XmlNode,
    add_keyframe_track,
    check_frame,
    check_frames_in_clip,
    labelled_runs,
    make_events,
    parse_xml,
    tighter,
    to_unit,
)

BALL_SHAPES = ("points", "ellipse", "box")
OTHER_SHAPES = ("polygon", "polyline", "cuboid", "skeleton", "mask")
VISIBILITY_ATTRIBUTE = "visibility"
"""Per-shape attribute carrying ball.csv's visibility 1..3 (written on export; optional on import)."""


# ---------------------------------------------------------------------------------------------- import
def _int(path: Path, node: XmlNode, name: str, default: int | None = None) -> int:
    raw = node.attrib.get(name)
    if raw is None:
        if default is not None:
            return default
        raise FormatError(
            path,
            f"<{node.tag}> has no {name!r} attribute",
            line=node.line,
            fix=f'write {name}="..." as CVAT for video 1.1 does',
        )
    try:
        return int(raw)
    except ValueError:
        raise FormatError(
            path,
            f"<{node.tag}> {name}={_cut(raw)} is not a whole number" + _too_long(raw),
            line=node.line,
            fix="write a whole number",
        ) from None


def _cut(text: str) -> str:
    """``repr(text)``, cut to a readable length for a message."""
    return repr(text) if len(text) <= 40 else repr(text[:37]) + "..."


def _too_long(text: str) -> str:
    """Why a run of thousands of digits is no number here (Python converts at most 4300)."""
    return f" (it has {len(text.strip())} digits)" if re.fullmatch(r"\s*[+-]?\d{100,}\s*", text) else ""


def _float(path: Path, node: XmlNode, name: str) -> float:
    raw = node.attrib.get(name)
    try:
        return float(raw) if raw is not None else float("nan")
    except ValueError:
        raise FormatError(
            path,
            f"<{node.tag}> {name}={raw!r} is not a number",
            line=node.line,
            fix="write a number (pixels)",
        ) from None


def _flag(path: Path, node: XmlNode, name: str) -> bool:
    return _int(path, node, name, default=0) != 0


def _centre(path: Path, node: XmlNode) -> tuple[float, float]:
    """Pixel centre of a ball shape: the point, the ellipse's centre or the box's centre."""
    if node.tag == "points":
        raw = node.attrib.get("points", "")
        pairs = [p for p in raw.split(";") if p.strip()]
        if len(pairs) != 1:
            raise FormatError(
                path,
                f"<points> holds {len(pairs)} points, the ball needs exactly one",
                line=node.line,
                fix='write points="x,y" (one pixel position per frame)',
            )
        try:
            x, y = (float(v) for v in pairs[0].split(","))
        except ValueError:
            raise FormatError(
                path,
                f"<points> points={raw!r} is not 'x,y'",
                line=node.line,
                fix='write points="x,y" in pixels',
            ) from None
        return x, y
    if node.tag == "ellipse":
        return _float(path, node, "cx"), _float(path, node, "cy")
    xtl, ytl, xbr, ybr = (_float(path, node, k) for k in ("xtl", "ytl", "xbr", "ybr"))
    return (xtl + xbr) / 2, (ytl + ybr) / 2


@dataclass
class _Frames:
    """CVAT frame numbers -> clip frames: ``(frame - start) / step + offset``, checked against ``limit``.

    ``start`` is the first video frame of the export (a job's own start), ``offset`` the task frame it
    is (the job's segment start), ``limit`` the frames a shape may lie on (None: :data:`MAX_FRAMES`).
    """

    path: Path
    start: int
    step: int
    offset: int
    limit: int | None
    stated: str
    kind: str = "task"

    def __call__(self, node: XmlNode, *, closing: bool = False) -> int:
        """The clip frame of ``node``; a ``closing`` outside shape may lie one frame past the end."""
        raw = _int(self.path, node, "frame")
        rel, rest = divmod(raw - self.start, self.step)
        if rel < 0 or rest:
            raise FormatError(
                self.path,
                f"frame {raw} is not a frame of the {self.kind} (start frame {self.start}, step {self.step})",
                line=node.line,
                fix=f"export the {self.kind} again",
            )
        limit = self.limit + 1 if closing and self.limit is not None else self.limit
        frame = rel + self.offset
        check_frame(self.path, frame, limit, where="", line=node.line, shown=raw, stated=self.stated)
        return frame


@dataclass
class _Header:
    """What the ``<meta>`` of an export says, checked and bounded."""

    kind: str  # "task" or "job"
    name: str
    width: float
    height: float
    n_frames: int | None  # the task's length (None for a job: its <size> is the job's)
    last_frame: int | None  # the last clip frame the export covers
    frames: _Frames


def _meta(path: Path, root: XmlNode) -> tuple[XmlNode, str, XmlNode]:
    """``(<task> or <job>, "task" or "job", <meta>)``."""
    meta = root.find("meta")
    if meta is None:
        raise FormatError(
            path, "no <meta> element", line=root.line, fix="export with CVAT's 'CVAT for video 1.1' format"
        )
    for kind in ("task", "job"):
        if (node := meta.find(kind)) is not None:
            return node, kind, meta
    project = meta.find("project")
    if project is not None:
        tasks = (project.find("tasks") or XmlNode("tasks", {}, 0)).findall("task")
        if len(tasks) != 1:
            raise FormatError(
                path,
                f"a project export with {len(tasks)} tasks",
                line=project.line,
                fix="export each task (one clip) on its own",
            )
        return tasks[0], "task", meta
    raise FormatError(
        path,
        "<meta> has no <task> or <job>",
        line=meta.line,
        fix="export a task or a job with 'CVAT for video 1.1'",
    )


def _whole(path: Path, node: XmlNode | None, default: int, low: int, high: int, unit: str = "") -> int:
    """The whole number in element ``node`` (``default`` when absent or empty), in ``low .. high``."""
    if node is None or not node.text.strip():
        return default
    text = node.text.strip()
    try:
        value = int(text)
    except ValueError:
        raise FormatError(
            path,
            f"<{node.tag}> {_cut(text)} is not a whole number" + _too_long(text),
            line=node.line,
            fix="export the task again",
        ) from None
    if value < low:
        raise FormatError(
            path, f"<{node.tag}> {value} is less than {low}", line=node.line, fix="export the task again"
        )
    if value > high:
        raise FormatError(
            path,
            f"<{node.tag}> {value} is more than {high}{unit}",
            line=node.line,
            fix="check the task: rally3d reads clips of at most " + MAX_FRAMES_TEXT,
        )
    return value


def _step(path: Path, node: XmlNode | None) -> int:
    """The frame step of ``<frame_filter>`` (``step=K``; empty: 1)."""
    text = node.text.strip() if node is not None else ""
    if not text:
        return 1
    found = re.fullmatch(r"step\s*=\s*(\d{1,9})", text)
    if found is None or int(found.group(1)) == 0:
        raise FormatError(
            path,
            f"<frame_filter> {text[:40]!r} is not a frame step (step=K with K = 1, 2, ...)",
            line=node.line if node is not None else None,
            fix="write the task's frame step as CVAT's task details show it, e.g. step=1 (every frame)",
        )
    return int(found.group(1))


def _image_size(
    path: Path, task: XmlNode, meta: XmlNode, size: tuple[int, int] | None
) -> tuple[float, float]:
    """``original_size`` (in ``<task>``, or in ``<meta>`` after ``</job>``), else ``size``."""
    node = task.find("original_size")
    if node is None:
        node = meta.find("original_size")
    if node is None:
        if size is not None:
            return float(size[0]), float(size[1])
        raise FormatError(
            path,
            f"the {task.tag} has no <original_size>, so pixel positions cannot be scaled",
            line=task.line,
            fix="pass --width and --height (the video's frame size in pixels): CVAT states it only for "
            "tasks made from a video file",
        )
    values = []
    for name in ("width", "height"):
        text = node.findtext(name) or ""
        try:
            value = float(text)
        except ValueError:
            value = float("nan")
        if not (np.isfinite(value) and 0 < value <= MAX_IMAGE_SIDE):
            raise FormatError(
                path,
                f"<original_size> <{name}> {text[:40]!r} is not a frame size (1 to {MAX_IMAGE_SIDE} pixels)",
                line=node.line,
                fix="write the video's frame size there, or delete <original_size> and pass --width "
                "and --height",
            )
        values.append(value)
    return values[0], values[1]


def _header(
    path: Path, root: XmlNode, size: tuple[int, int] | None, clip_frames: int | None
) -> tuple[_Header, list[str]]:
    """Read and bound the export's ``<meta>``: layout, frame size, length, start frame and step."""
    task, kind, meta = _meta(path, root)
    width, height = _image_size(path, task, meta, size)
    length = _whole(path, task.find("size"), 0, 1, MAX_FRAMES, f" frames ({MAX_FRAMES_TEXT})") or None
    start = _whole(path, task.find("start_frame"), 0, 0, 10**12)
    step = _step(path, task.find("frame_filter"))
    offset = 0
    if kind == "job":  # frames are the task's: the job starts at its segment's first frame
        segments = task.find("segments")
        segment = segments.find("segment") if segments is not None else None
        offset = _whole(path, segment.find("start") if segment is not None else None, 0, 0, MAX_FRAMES)
    warnings = []
    task_start = start - offset * step
    if task_start or step != 1:
        warnings.append(
            f"{path}: task frames start at video frame {task_start} with step {step}; clip frame i is "
            f"video frame {task_start} + {step}*i"
        )
    if kind == "task":
        limit, stated, n_frames = length, f"the task's {length} frames", length
    else:
        limit = offset + length if length else None
        stated, n_frames = f"the job's frames (task frames {offset} to {offset + (length or 1) - 1})", None
    last_frame = limit - 1 if limit else None
    frames = _Frames(path, start, step, offset, *tighter(limit, stated, clip_frames), kind)
    name = task.findtext("name") or ""
    header = _Header(kind, name, width, height, n_frames, last_frame, frames)
    return header, warnings


def import_cvat(
    path: str | Path,
    labels: LabelMap | None = None,
    *,
    size: tuple[int, int] | None = None,
    clip_frames: int | None = None,
) -> Imported:
    """Read a "CVAT for video 1.1" ``annotations.xml`` (a task or a job export) into a ball track and events.

    Args:
        path: the XML file (unzipped from CVAT's export).
        labels: which labels are the ball and which are events (default: ``ball`` and the nine
            event labels of docs/formats.md §9).
        size: ``(width, height)`` of the video, used when the file states no ``original_size``.
        clip_frames: the length of the clip the labels go into, when known: frames must lie below it
            (checked, like the file's own length, before anything is built).

    Returns:
        :class:`~inference.interchange.common.Imported`; frames are task frames counted from the task's
        start frame (divided by its frame step); coordinates are normalised by ``original_size``.
        ``n_frames`` is the task's ``<size>`` (None for a job export, whose size is the job's).
    """
    path = Path(path)
    labels = labels or LabelMap()
    root = parse_xml(path)
    if root.tag != "annotations":
        raise FormatError(
            path,
            f"the root element is <{root.tag}>, not <annotations>",
            line=root.line,
            fix="pass CVAT's annotations.xml (export format 'CVAT for video 1.1')",
        )
    warnings: list[str] = []
    version = root.findtext("version")
    if version and not version.startswith("1."):
        warnings.append(f"{path}: format version {version}; this reader knows 1.1")
    _meta(path, root)
    if root.findall("image"):
        raise FormatError(
            path,
            "this is a 'CVAT for images' export (it has <image> elements)",
            line=root.findall("image")[0].line,
            fix="export the task again as 'CVAT for video 1.1'",
        )
    head, notes = _header(path, root, size, clip_frames)
    warnings += notes
    clip_frame, width, height = head.frames, head.width, head.height

    rows = Rows(path)
    found: dict[int, list[tuple[str, str]]] = {}
    skipped: dict[str, int] = {}
    for track in root.findall("track"):
        name = track.attrib.get("label", "")
        kind = labels.kind(name)
        shapes = [c for c in track.children if c.tag in BALL_SHAPES + OTHER_SHAPES]
        if kind is None:
            skipped[name] = skipped.get(name, 0) + 1
            continue
        if kind == "event":
            for shape in shapes:
                if not _flag(path, shape, "outside") and _int(path, shape, "keyframe", default=1):
                    found.setdefault(clip_frame(shape), []).append(
                        (labels.events[name], f"line {shape.line}")
                    )
            continue
        if kind != BALL:
            continue
        keys = [_ball_key(path, shape, clip_frame, width, height) for shape in shapes]
        if add_keyframe_track(rows, keys, last_frame=head.last_frame, end_marker=True):
            warnings.append(
                f"{path}, line {track.line}: the ball track ends on a visible keyframe; CVAT "
                f"repeats it to the end of the {head.kind}, rows stop at that keyframe"
            )
    for tag in root.findall("tag"):
        name = tag.attrib.get("label", "")
        kind = labels.kind(name)
        if kind == "event":
            found.setdefault(clip_frame(tag), []).append((labels.events[name], f"line {tag.line}"))
        elif kind is None:
            skipped[name] = skipped.get(name, 0) + 1
    for name, count in sorted(skipped.items()):
        warnings.append(
            f"{path}: skipped {count} track(s)/tag(s) with the unknown label {name!r}: "
            + labels.unknown_hint(name)
        )
    ball = rows.track()
    check_frames_in_clip(path, ball, head.n_frames)
    events = make_events(path, found, head.n_frames)
    if head.kind == "task":
        source = f"CVAT task {head.name or path.stem!r} ({path.name})"
    else:
        source = f"CVAT job {root.findtext('meta/job/id') or '?'} ({path.name})"
    return Imported(ball, events, round(width), round(height), head.n_frames, None, source, warnings)


def _ball_key(path: Path, shape: XmlNode, clip_frame: _Frames, width: float, height: float) -> Key:
    where = f"line {shape.line}"
    if shape.tag in OTHER_SHAPES:
        raise FormatError(
            path,
            f"<{shape.tag}> in a ball track; the ball is a point, an ellipse or a box",
            line=shape.line,
            fix="draw the ball with the points (or ellipse) tool",
        )
    outside = _flag(path, shape, "outside")
    frame = clip_frame(shape, closing=outside)
    if outside:
        return Key(frame, None, 0, False, where)
    visibility = 3 if _flag(path, shape, "occluded") else 1
    for attribute in shape.findall("attribute"):
        if attribute.attrib.get("name") == VISIBILITY_ATTRIBUTE and attribute.text.strip():
            text = attribute.text.strip()
            if text not in ("1", "2", "3"):
                raise FormatError(
                    path,
                    f"visibility attribute {text!r} is not 1, 2 or 3",
                    line=attribute.line,
                    fix='1 visible, 2 hard to see, 3 occluded; a ball not in the frame is outside="1"',
                )
            visibility = int(text)
    x, y = _centre(path, shape)
    return Key(frame, to_unit(path, where, x, y, width, height, line=shape.line), visibility, True, where)


# ---------------------------------------------------------------------------------------------- export
def _shape(
    frame: int, xy_px: tuple[float, float], *, outside: bool, occluded: bool, visibility: int | None
) -> str:
    attrs = (
        f'frame="{frame}" keyframe="1" outside="{int(outside)}" occluded="{int(occluded)}" '
        f'points="{xy_px[0]:.6f},{xy_px[1]:.6f}" z_order="0"'
    )
    if visibility is None:
        return f"    <points {attrs}>\n    </points>\n"
    return (
        f"    <points {attrs}>\n"
        f'      <attribute name="{VISIBILITY_ATTRIBUTE}">{visibility}</attribute>\n    </points>\n'
    )


def _labels_xml(event_labels: list[str]) -> str:
    """``<labels>``: ``ball`` (points, a mutable ``visibility`` attribute 1..3) and the event labels."""

    def label(name: str, attributes: str) -> str:
        return (
            f"        <label>\n          <name>{escape(name)}</name>\n          <type>points</type>\n"
            f"          <attributes>\n{attributes}          </attributes>\n        </label>\n"
        )

    visibility = (
        "            <attribute>\n              <name>visibility</name>\n"
        "              <mutable>True</mutable>\n              <input_type>select</input_type>\n"
        "              <default_value>1</default_value>\n              <values>1\n2\n3</values>\n"
        "            </attribute>\n"
    )
    return (
        "      <labels>\n"
        + label(BALL, visibility)
        + "".join(label(e, "") for e in event_labels)
        + "      </labels>\n"
    )


def export_cvat(
    path: str | Path,
    track: BallTrack,
    events: HitEvents,
    *,
    width: int,
    height: int,
    n_frames: int,
    name: str = "rally3d clip",
    event_labels: tuple[str, ...] = EVENT_LABELS,
) -> Path:
    """Write a ball track and events as a "CVAT for video 1.1" ``annotations.xml``.

    One ``ball`` points track per run of consecutive labelled frames, every row a keyframe (visible:
    the position, ``occluded`` for visibility 3, the ``visibility`` attribute 1..3; visibility 0:
    ``outside``), closed by an ``outside`` shape on the frame after the run. Each event is a one-frame
    points track labelled with the event, on the ball's position (the image centre when unknown).
    Pixels with 6 decimals; CVAT re-interpolates only between keyframes, so every row is one.
    """
    size = np.array([width, height], dtype=float)
    centre = (width / 2, height / 2)
    xy_px = track.to_pixels(width, height)
    out = [
        '<?xml version="1.0" encoding="utf-8"?>\n<annotations>\n  <version>1.1</version>\n  <meta>\n',
        "    <task>\n",
        f"      <name>{escape(name)}</name>\n      <size>{n_frames}</size>\n",
        "      <mode>interpolation</mode>\n      <overlap>0</overlap>\n      <flipped>False</flipped>\n",
        f"      <start_frame>0</start_frame>\n      <stop_frame>{n_frames - 1}</stop_frame>\n",
        "      <frame_filter></frame_filter>\n",
        _labels_xml(list(event_labels)),
        f"      <original_size>\n        <width>{width}</width>\n        <height>{height}</height>\n"
        "      </original_size>\n    </task>\n  </meta>\n",
    ]
    track_id = 0
    for run in labelled_runs(track):
        out.append(f'  <track id="{track_id}" label="ball" source="manual">\n')
        last = centre
        for i in run:
            vis = int(track.visibility[i])
            if vis > 0:
                last = (float(xy_px[i, 0]), float(xy_px[i, 1]))
            out.append(
                _shape(int(track.frame[i]), last, outside=vis == 0, occluded=vis == 3, visibility=vis or None)
            )
        end = int(track.frame[run[-1]]) + 1
        if end < n_frames:
            out.append(_shape(end, last, outside=True, occluded=False, visibility=None))
        out.append("  </track>\n")
        track_id += 1
    for frame, label in zip(events.frame.tolist(), events.event.tolist()):
        at = track.at(frame)
        xy = tuple(at[1] * size) if at is not None and at[0] > 0 else centre
        out.append(f'  <track id={quoteattr(str(track_id))} label={quoteattr(label)} source="manual">\n')
        out.append(_shape(frame, xy, outside=False, occluded=False, visibility=None))
        if frame + 1 < n_frames:
            out.append(_shape(frame + 1, xy, outside=True, occluded=False, visibility=None))
        out.append("  </track>\n")
        track_id += 1
    out.append("</annotations>\n")
    return atomic_write_text(path, "".join(out))
