"""CVAT for video 1.1 (XML) <-> clip folder: the ball track and the events (docs/interchange.md).

A CVAT task in interpolation mode holds ``<track label=...>`` elements of per-frame shapes with
``frame``, ``outside``, ``occluded`` and ``keyframe``. The ball is a ``points`` (or ``ellipse``, or
``box``) track in pixels of ``meta/original_size``; events are tracks (or shapes) whose label is an
event label, or root-level ``<tag frame label>`` elements.
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import escape, quoteattr

import numpy as np

from inference.clipio import EVENT_LABELS, BallTrack, FormatError, HitEvents
from inference.clipio.atomic import atomic_write_text

from .common import (
    BALL,
    Imported,
    Key,
    LabelMap,
    Rows,
    XmlNode,
    add_keyframe_track,
    check_frames_in_clip,
    labelled_runs,
    make_events,
    parse_xml,
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
            f"<{node.tag}> {name}={raw!r} is not a whole number",
            line=node.line,
            fix="write a whole number",
        ) from None


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


class _Frames:
    """CVAT frame numbers -> clip frames: ``(frame - start_frame) / step``."""

    def __init__(self, path: Path, start: int, step: int):
        self.path, self.start, self.step = path, start, step

    def __call__(self, node: XmlNode) -> int:
        raw = _int(self.path, node, "frame")
        rel, rest = divmod(raw - self.start, self.step)
        if rel < 0 or rest:
            raise FormatError(
                self.path,
                f"frame {raw} is not a frame of the task (start frame {self.start}, step {self.step})",
                line=node.line,
                fix="export the task again",
            )
        return rel


def _meta(path: Path, root: XmlNode) -> tuple[XmlNode, list[str]]:
    meta = root.find("meta")
    warnings: list[str] = []
    if meta is None:
        raise FormatError(
            path, "no <meta> element", line=root.line, fix="export with CVAT's 'CVAT for video 1.1' format"
        )
    for name in ("task", "job"):
        if (node := meta.find(name)) is not None:
            return node, warnings
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
        return tasks[0], warnings
    raise FormatError(
        path,
        "<meta> has no <task> or <job>",
        line=meta.line,
        fix="export a task or a job with 'CVAT for video 1.1'",
    )


def import_cvat(path: str | Path, labels: LabelMap | None = None) -> Imported:
    """Read a "CVAT for video 1.1" ``annotations.xml`` into a ball track and events.

    Args:
        path: the XML file (unzipped from CVAT's export).
        labels: which labels are the ball and which are events (default: ``ball`` and the nine
            event labels of docs/formats.md §9).

    Returns:
        :class:`~inference.interchange.common.Imported`; frames are task frames counted from the task's
        start frame (divided by its frame step); coordinates are normalised by ``original_size``.
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
    task, _ = _meta(path, root)
    if root.findall("image"):
        raise FormatError(
            path,
            "this is a 'CVAT for images' export (it has <image> elements)",
            line=root.findall("image")[0].line,
            fix="export the task again as 'CVAT for video 1.1'",
        )
    width_text, height_text = task.findtext("original_size/width"), task.findtext("original_size/height")
    try:
        width, height = float(width_text or "nan"), float(height_text or "nan")
        size_text = task.findtext("size")
        n_frames = int(size_text) if size_text else None
        start = int(task.findtext("start_frame") or 0)
        step_text = (task.findtext("frame_filter") or "").strip()
        step = int(step_text.split("=")[1]) if step_text.startswith("step=") else 1
    except (ValueError, IndexError):
        raise FormatError(
            path,
            "the task's <size>, <original_size>, <start_frame> or <frame_filter> is not a number",
            line=task.line,
            fix="export the task again",
        ) from None
    if not (np.isfinite(width) and np.isfinite(height) and width > 0 and height > 0):
        raise FormatError(
            path,
            "the task has no <original_size> with <width> and <height>",
            line=task.line,
            fix="export with 'CVAT for video 1.1' (it states the frame size)",
        )
    if start or step != 1:
        warnings.append(
            f"{path}: task frames start at video frame {start} with step {step}; clip frame i is "
            f"video frame {start} + {step}*i"
        )
    clip_frame = _Frames(path, start, step)
    last_frame = n_frames - 1 if n_frames else None

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
        if add_keyframe_track(rows, keys, last_frame=last_frame, end_marker=True):
            warnings.append(
                f"{path}, line {track.line}: the ball track ends on a visible keyframe; CVAT "
                "repeats it to the end of the task, rows stop at that keyframe"
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
    check_frames_in_clip(path, ball, n_frames)
    events = make_events(path, found, n_frames)
    name = task.findtext("name") or path.stem
    return Imported(
        ball,
        events,
        round(width),
        round(height),
        n_frames,
        None,
        f"CVAT task {name!r} ({path.name})",
        warnings,
    )


def _ball_key(path: Path, shape: XmlNode, clip_frame: _Frames, width: float, height: float) -> Key:
    where = f"line {shape.line}"
    if shape.tag in OTHER_SHAPES:
        raise FormatError(
            path,
            f"<{shape.tag}> in a ball track; the ball is a point, an ellipse or a box",
            line=shape.line,
            fix="draw the ball with the points (or ellipse) tool",
        )
    frame = clip_frame(shape)
    if _flag(path, shape, "outside"):
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
