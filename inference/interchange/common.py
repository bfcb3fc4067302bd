"""What the CVAT and Label Studio converters share: labels, keyframe tracks, safe XML, writing a clip.

The mapping itself is documented in docs/interchange.md. Everything here speaks clip-folder terms:
frames are zero-based, coordinates normalised to ``[0, 1]`` (docs/formats.md §2).
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path

import numpy as np

from inference.clipio import EVENT_LABELS, BallTrack, Clip, ClipInfo, FormatError, HitEvents
from inference.clipio.csvtable import closest, read_text

BALL = "ball"
IGNORE = "ignore"
EDGE_TOLERANCE_PX = 1.0
"""A ball centre at most this far outside the image (pixels) is moved onto its edge; further is an error."""


# ---------------------------------------------------------------------------------------------- labels
@dataclass
class LabelMap:
    """Which outside label means the ball, which means which ``events.csv`` event, which to skip.

    Attributes:
        ball: outside labels that name the ball (default ``{"ball"}``).
        events: outside label -> event label of docs/formats.md §9 (the nine labels map to themselves).
        ignore: outside labels skipped without a warning.
    """

    ball: set[str] = field(default_factory=lambda: {BALL})
    events: dict[str, str] = field(default_factory=lambda: {e: e for e in EVENT_LABELS})
    ignore: set[str] = field(default_factory=set)

    @classmethod
    def parse(cls, pairs: Iterable[str]) -> LabelMap:
        """Build from ``NAME=TARGET`` strings; TARGET is ``ball``, an event label or ``ignore``."""
        lm = cls()
        for pair in pairs:
            name, sep, target = (s.strip() for s in pair.partition("="))
            if not sep or not name or not target:
                raise ValueError(f"--label-map {pair!r}: expected NAME=TARGET, e.g. bounce=ground")
            lm.add(name, target)
        return lm

    def add(self, name: str, target: str) -> None:
        """Map the outside label ``name`` to ``target`` (``ball``, an event label or ``ignore``)."""
        for table in (self.ball, self.ignore):
            table.discard(name)
        self.events.pop(name, None)
        if target == BALL:
            self.ball.add(name)
        elif target == IGNORE:
            self.ignore.add(name)
        elif target in EVENT_LABELS:
            self.events[name] = target
        else:
            hint = closest(target, (*EVENT_LABELS, BALL, IGNORE))
            raise ValueError(
                f"label map target {target!r} is not 'ball', 'ignore' or an event label"
                + (f" (did you mean {hint!r}?)" if hint else "")
                + f"; event labels: {', '.join(EVENT_LABELS)}"
            )

    def kind(self, name: str) -> str | None:
        """``"ball"``, ``"event"``, ``"ignore"`` or None (unknown) for the outside label ``name``."""
        if name in self.ball:
            return BALL
        if name in self.events:
            return "event"
        if name in self.ignore:
            return IGNORE
        return None

    def unknown_hint(self, name: str) -> str:
        """A fix for an unknown label: the closest known one and the ``--label-map`` to write."""
        hint = closest(name, (*self.ball, *self.events))
        return (f"did you mean {hint!r}? " if hint else "") + (
            f"map it with --label-map {name}=<ball|{'|'.join(EVENT_LABELS)}|ignore>"
        )


# ------------------------------------------------------------------------------------------- keyframes
@dataclass
class Key:
    """One keyframe of an outside track, already in clip terms.

    Attributes:
        frame: zero-based clip frame.
        xy: normalised ``(u, v)``, or None where the tool hides the object (CVAT ``outside``).
        visibility: ball.csv code 1..3 where ``xy`` is set (0 where hidden).
        carry_on: whether the tool fills the frames up to the next key (interpolation) or leaves them
            hidden (CVAT: the key is not ``outside``; Label Studio: ``enabled``).
        where: the key's place in the file, for messages (``line 57``, ``sequence[3]``).
    """

    frame: int
    xy: tuple[float, float] | None
    visibility: int
    carry_on: bool
    where: str


@dataclass
class Rows:
    """Ball rows collected from several tracks: ``{frame: (visibility, u, v, where)}``."""

    path: Path
    rows: dict[int, tuple[int, float, float, str]] = field(default_factory=dict)

    def put(self, frame: int, visibility: int, xy: tuple[float, float] | None, where: str) -> None:
        """Add a row; a frame given twice must agree (a visible row beats a hidden one)."""
        u, v = xy if xy is not None else (np.nan, np.nan)
        old = self.rows.get(frame)
        if old is not None:
            if visibility == 0:
                return  # a hidden row never replaces a row (a visible one wins)
            same = old[0] == visibility and np.allclose(old[1:3], (u, v), atol=1e-6)
            if old[0] > 0 and not same:
                raise FormatError(
                    self.path,
                    f"{where}: frame {frame} has a second, different ball position "
                    f"(the first is at {old[3]})",
                    fix="keep one ball track per frame: delete or split the overlapping track",
                )
        self.rows[frame] = (int(visibility), float(u), float(v), where)

    def track(self) -> BallTrack:
        """The rows as a :class:`BallTrack` (sorted by frame)."""
        if not self.rows:
            return BallTrack.empty()
        frames = sorted(self.rows)
        vis = [self.rows[f][0] for f in frames]
        xy = [[self.rows[f][1], self.rows[f][2]] if self.rows[f][0] > 0 else [np.nan, np.nan] for f in frames]
        return BallTrack(frames, vis, xy)


def add_keyframe_track(rows: Rows, keys: list[Key], *, last_frame: int | None, end_marker: bool) -> bool:
    """Spread one outside track over frames, the way the tool shows it, into ``rows``.

    A key gives a row at its frame. Between a key with ``carry_on`` and the next, ``xy`` is linear and
    the visibility is the earlier key's; between a hidden-after key and the next, the ball is not in
    the frame (visibility 0). After the last key there are no rows. With ``end_marker`` (CVAT), a final
    hidden key only closes the track, unless it lies on ``last_frame``, the clip's last frame.

    Returns:
        True when the track stops on a key that would carry on (the tool repeats it to the end).
    """
    keys = sorted(keys, key=lambda k: k.frame)
    for a, b in pairwise(keys):
        if a.frame == b.frame:
            raise FormatError(
                rows.path,
                f"{b.where}: a second keyframe on frame {b.frame} in the same track "
                f"(the first is at {a.where})",
                fix="keep one shape per frame and track",
            )
    for i, key in enumerate(keys):
        is_last = i == len(keys) - 1
        if is_last and end_marker and key.xy is None and key.frame != last_frame and i > 0:
            break
        rows.put(key.frame, key.visibility if key.xy is not None else 0, key.xy, key.where)
        if is_last:
            break
        nxt = keys[i + 1]
        span = nxt.frame - key.frame
        for f in range(key.frame + 1, nxt.frame):
            if key.carry_on and key.xy is not None:
                t = (f - key.frame) / span
                end = nxt.xy if nxt.xy is not None else key.xy
                xy = (key.xy[0] + t * (end[0] - key.xy[0]), key.xy[1] + t * (end[1] - key.xy[1]))
                rows.put(f, key.visibility, xy, f"{key.where} (interpolated)")
            else:
                rows.put(f, 0, None, f"{key.where} (hidden)")
    return bool(keys) and keys[-1].xy is not None and keys[-1].carry_on and keys[-1].frame != last_frame


def runs(frames: np.ndarray) -> list[np.ndarray]:
    """Indices of sorted ``frames`` split into runs of consecutive frames."""
    if not len(frames):
        return []
    return np.split(np.arange(len(frames)), np.flatnonzero(np.diff(frames) > 1) + 1)


def labelled_runs(track: BallTrack) -> list[np.ndarray]:
    """A track's row indices in runs of consecutive frames (a gap = frames not labelled)."""
    return runs(track.frame)


def to_unit(
    path: Path, where: str, x: float, y: float, width: float, height: float, line: int | None = None
) -> tuple[float, float]:
    """Pixel ``(x, y)`` of a ``width x height`` image -> normalised; a centre off the image is an error.

    The error names ``line`` when given (XML), else starts with ``where``.
    """
    tol = EDGE_TOLERANCE_PX
    prefix = "" if line is not None else f"{where}: "
    if not (np.isfinite(x) and np.isfinite(y)):
        raise FormatError(path, f"{prefix}coordinate is not a finite number", line=line, fix="write numbers")
    if x < -tol or y < -tol or x > width + tol or y > height + tol:
        raise FormatError(
            path,
            f"{prefix}ball centre ({x:g}, {y:g}) lies outside the {width:g}x{height:g} image",
            line=line,
            fix="check the frame size of the task, or mark the ball outside on this frame",
        )
    return min(max(x / width, 0.0), 1.0), min(max(y / height, 0.0), 1.0)


# -------------------------------------------------------------------------------------------- results
@dataclass
class Imported:
    """Labels read from an outside tool's file, in clip-folder terms.

    Attributes:
        ball: the ball rows (``ball.csv``).
        events: the events (``events.csv``).
        width, height: image size the file states (None when it states none).
        n_frames: number of frames the file states (None when unknown).
        fps: frame rate the file states (None when unknown).
        source: a short description for ``clip.yaml``'s ``source``.
        warnings: things skipped or guessed, one line each.
    """

    ball: BallTrack
    events: HitEvents
    width: int | None = None
    height: int | None = None
    n_frames: int | None = None
    fps: float | None = None
    source: str = ""
    warnings: list[str] = field(default_factory=list)


def make_events(path: Path, found: Mapping[int, list[tuple[str, str]]], n_frames: int | None) -> HitEvents:
    """``{frame: [(event, where), ...]}`` -> :class:`HitEvents`; two events on one frame is an error."""
    frames, labels = [], []
    for frame in sorted(found):
        items = sorted(set(found[frame]), key=lambda t: t[1])
        distinct = sorted({e for e, _ in items})
        if len(distinct) > 1:
            raise FormatError(
                path,
                f"frame {frame} has two events, {distinct[0]!r} ({items[0][1]}) and {distinct[1]!r}",
                fix="events.csv holds one event per frame: move the later "
                "contact to the next frame (docs/formats.md §9)",
            )
        if frame < 0 or (n_frames is not None and frame >= n_frames):
            raise FormatError(
                path,
                f"{items[0][1]}: event on frame {frame}, outside the clip's {n_frames} frames",
                fix="delete it or check the task's frame range",
            )
        frames.append(frame)
        labels.append(distinct[0])
    return HitEvents(frames, labels) if frames else HitEvents.empty()


def check_frames_in_clip(path: Path, track: BallTrack, n_frames: int | None) -> None:
    """Ball rows must lie inside the clip when its length is known."""
    if n_frames is not None and len(track) and track.frame[-1] >= n_frames:
        raise FormatError(
            path,
            f"ball on frame {int(track.frame[-1])}, but the clip has {n_frames} frames",
            fix="check that the task holds this clip's frames (start frame, frame step)",
        )


# ------------------------------------------------------------------------------------------ safe XML
@dataclass
class XmlNode:
    """A parsed XML element with the line it starts on (for error messages)."""

    tag: str
    attrib: dict[str, str]
    line: int
    children: list[XmlNode] = field(default_factory=list)
    text: str = ""

    def find(self, tag: str) -> XmlNode | None:
        return next((c for c in self.children if c.tag == tag), None)

    def findall(self, tag: str) -> list[XmlNode]:
        return [c for c in self.children if c.tag == tag]

    def findtext(self, path: str) -> str | None:
        node: XmlNode | None = self
        for part in path.split("/"):
            node = node.find(part) if node is not None else None
        return node.text.strip() if node is not None else None


def parse_xml(path: str | Path) -> XmlNode:
    """Parse an untrusted XML file into :class:`XmlNode`s, refusing DTDs and entities.

    ``defusedxml`` does the parsing when it is installed; otherwise the standard SAX parser, after a
    check that rejects any ``<!DOCTYPE`` or ``<!ENTITY`` (so no entity expansion, no external fetch).
    Malformed XML raises :class:`FormatError` with the line.
    """
    import xml.sax
    from xml.sax.handler import ContentHandler

    path = Path(path)
    text = read_text(path)
    upper = text.upper()
    if "<!DOCTYPE" in upper or "<!ENTITY" in upper:
        line = text[: max(upper.find("<!DOCTYPE"), upper.find("<!ENTITY"))].count("\n") + 1
        raise FormatError(
            path,
            "the XML declares a DOCTYPE or ENTITY, which is refused for safety",
            line=line,
            fix="export the annotations again from CVAT (its files have no DOCTYPE)",
        )

    class Builder(ContentHandler):
        def __init__(self) -> None:
            super().__init__()
            self.stack: list[XmlNode] = [XmlNode("#document", {}, 0)]
            self.locator = None

        def setDocumentLocator(self, locator) -> None:
            self.locator = locator

        def startElement(self, name, attrs) -> None:
            line = self.locator.getLineNumber() if self.locator else 0
            node = XmlNode(name, {k: attrs[k] for k in attrs.getNames()}, line)
            self.stack[-1].children.append(node)
            self.stack.append(node)

        def endElement(self, name) -> None:
            self.stack.pop()

        def characters(self, content) -> None:
            self.stack[-1].text += content

    builder = Builder()
    data = text.encode("utf-8")
    try:
        try:
            import defusedxml.sax as safe_sax
        except ImportError:
            xml.sax.parseString(data, builder)
        else:
            safe_sax.parseString(data, builder, forbid_dtd=True)
    except xml.sax.SAXParseException as e:
        raise FormatError(
            path,
            f"not well-formed XML ({e.getMessage()}, column {e.getColumnNumber()})",
            line=e.getLineNumber(),
            fix="export the file again; it may be cut short",
        ) from None
    except ValueError as e:  # defusedxml's DTDForbidden, EntitiesForbidden, ExternalReferenceForbidden
        raise FormatError(
            path,
            f"refused for safety: {type(e).__name__}",
            fix="export the annotations again from CVAT (its files have no DOCTYPE)",
        ) from None
    roots = builder.stack[0].children
    if not roots:
        raise FormatError(path, "no XML element", fix="export the annotations again")
    return roots[0]


# ------------------------------------------------------------------------------------ writing a clip
def backup(path: Path, clip_root: Path) -> Path:
    """Copy ``path`` to ``<clip>/.rally3d/backup/<name>.<YYYYmmdd-HHMMSS>`` and return the copy."""
    folder = clip_root / ".rally3d" / "backup"
    folder.mkdir(parents=True, exist_ok=True)
    dest = folder / f"{path.name}.{time.strftime('%Y%m%d-%H%M%S')}"
    shutil.copy2(path, dest)
    return dest


def _known_frames(clip: Clip) -> int | None:
    """The clip's frame count: clip.yaml's, else the video's; None when neither can be read."""
    try:
        return clip.n_frames
    except (FormatError, FileNotFoundError, OSError):
        return None


def write_into_clip(
    clip_root: str | Path,
    imported: Imported,
    *,
    overwrite: bool = False,
    sport: str | None = None,
    fps: float | None = None,
    video: str | None = None,
) -> tuple[Clip, list[str]]:
    """Write imported labels into a clip folder (``ball.csv``, ``events.csv``; ``clip.yaml`` if new).

    An existing ``clip.yaml`` is kept; its image must have the file's aspect ratio and hold its frames.
    A new one needs ``sport`` and a frame rate (``fps`` or the file's), and the image size from the file.
    Existing ``ball.csv``/``events.csv`` are replaced only with ``overwrite`` (a backup is kept).

    Returns:
        The clip and the lines to report (written files, backups).
    """
    clip = Clip(clip_root)
    report: list[str] = []
    if clip.clip_yaml_path.is_file():
        info = clip.info
        if imported.width and imported.height:
            ratio_file, ratio_clip = imported.width / imported.height, info.width / info.height
            if abs(ratio_file / ratio_clip - 1) > 0.01:
                raise FormatError(
                    clip.clip_yaml_path,
                    f"the clip is {info.width}x{info.height} but the "
                    f"imported file is {imported.width}x{imported.height} (another aspect ratio)",
                    fix="import into the clip made from the same video",
                )
        n_frames = _known_frames(clip)
        if n_frames and imported.n_frames and imported.n_frames != n_frames:
            report.append(
                f"warning: the file states {imported.n_frames} frames, the clip has {n_frames}: "
                "check that it was made from this clip's video"
            )
    else:
        missing = [
            flag
            for flag, ok in (
                ("--sport", sport),
                ("--fps", fps or imported.fps),
                ("--width/--height", imported.width and imported.height),
            )
            if not ok
        ]
        if missing:
            raise FormatError(
                clip.clip_yaml_path,
                "no clip.yaml yet, and the imported file does not give what a new one needs",
                fix=f"create the clip first, or pass {' '.join(missing)}",
            )
        info = ClipInfo(
            sport=sport,
            fps=float(fps or imported.fps),
            width=imported.width,
            height=imported.height,
            video=video or "video.mp4",
            n_frames=imported.n_frames,
            source=imported.source or None,
        )
        n_frames = info.n_frames
    check_frames_in_clip(clip.root, imported.ball, n_frames)
    if n_frames is not None and len(imported.events) and imported.events.frame[-1] >= n_frames:
        raise FormatError(
            clip.root,
            f"event on frame {int(imported.events.frame[-1])}, but the clip has {n_frames} frames",
            fix="check that the task holds this clip's frames",
        )
    targets = [(clip.ball_path, len(imported.ball)), (clip.events_path, len(imported.events))]
    existing = [p for p, _ in targets if p.exists()]
    if existing and not overwrite:
        raise FormatError(
            existing[0],
            "exists already; nothing was written",
            fix="pass --overwrite to replace it (a backup goes to .rally3d/backup/)",
        )
    for p in existing:
        report.append(f"backup {backup(p, clip.root)}")
    if not clip.clip_yaml_path.is_file():
        clip.root.mkdir(parents=True, exist_ok=True)
        report.append(f"wrote {clip.write_info(info)}")
    report.append(f"wrote {clip.write_ball(imported.ball)} ({len(imported.ball)} rows)")
    report.append(f"wrote {clip.write_events(imported.events)} ({len(imported.events)} events)")
    return clip, report
