"""What the CVAT and Label Studio converters share: labels, keyframe tracks, safe XML, writing a clip.

The mapping itself is documented in docs/interchange.md. Everything here speaks clip-folder terms:
frames are zero-based, coordinates normalised to ``[0, 1]`` (docs/formats.md §2).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from itertools import pairwise
from pathlib import Path

import numpy as np

from inference.clipio import EVENT_LABELS, BallTrack, Clip, ClipInfo, FormatError, HitEvents
from inference.clipio.atomic import replace_keeping_backup
from inference.clipio.tables import MAX_FRAMES, MAX_FRAMES_TEXT  # noqa: F401 - the importers' bound too
from inference.clipio.csvfiles import write_ball_csv, write_events_csv
from inference.clipio.csvtable import closest, read_text

BALL = "ball"
IGNORE = "ignore"
EDGE_TOLERANCE_PX = 1.0
"""A ball centre at most this far outside the image (pixels) is moved onto its edge; further is an error."""
MAX_IMAGE_SIDE = 65_536
"""Largest image width or height (pixels) a file may state (16K video is 15,360 wide)."""


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
class RowTable:
    """Ball rows as arrays, one row per entry.

    Attributes:
        frame: ``(N,) int64`` zero-based clip frames.
        visibility: ``(N,) int8`` ball.csv codes 0..3.
        xy: ``(N, 2) float64`` normalised ``(u, v)``, NaN where ``visibility == 0``.
        source: ``(N,) int32`` index into :attr:`Rows.wheres`, the row's place in the file.
    """

    frame: np.ndarray
    visibility: np.ndarray
    xy: np.ndarray
    source: np.ndarray

    @classmethod
    def empty(cls) -> RowTable:
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int8), np.zeros((0, 2)), np.zeros(0, np.int32))

    def __len__(self) -> int:
        return len(self.frame)

    def take(self, index: np.ndarray | slice) -> RowTable:
        """The rows at ``index`` (a boolean mask, indices or a slice)."""
        return RowTable(self.frame[index], self.visibility[index], self.xy[index], self.source[index])

    @classmethod
    def concat(cls, tables: list[RowTable]) -> RowTable:
        if not tables:
            return cls.empty()
        keys = ("frame", "visibility", "xy", "source")
        return cls(*(np.concatenate([getattr(t, k) for t in tables]) for k in keys))


class Rows:
    """Ball rows collected from several tracks, as arrays (memory in proportion to the rows).

    Blocks of rows are added with :meth:`add`; :meth:`table` merges them, one row per frame: on a frame given
    twice a visible row beats a hidden one, and two visible rows must agree.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        self.wheres: list[str] = []
        self._blocks: list[RowTable] = []
        self._merged = True

    def source(self, where: str) -> int:
        """Register a place in the file (``line 57``, ``sequence[3] (interpolated)``); its index."""
        self.wheres.append(where)
        return len(self.wheres) - 1

    def add(self, frame: np.ndarray, visibility: np.ndarray, xy: np.ndarray, source: np.ndarray) -> None:
        """Add rows (arrays as in :class:`RowTable`, taken over; ``xy`` of hidden rows becomes NaN)."""
        block = RowTable(
            np.asarray(frame, np.int64),
            np.asarray(visibility, np.int8),
            np.asarray(xy, np.float64),
            np.asarray(source, np.int32),
        )
        block.xy[block.visibility == 0] = np.nan
        if len(block):
            self._blocks.append(block)
            self._merged = len(self._blocks) == 1 and bool(np.all(block.frame[1:] > block.frame[:-1]))

    def table(self) -> RowTable:
        """All rows merged, sorted by frame, one per frame (raises on two different visible rows)."""
        if not self._merged:
            self._blocks = [self._merge(RowTable.concat(self._blocks))]
            self._merged = True
        return self._blocks[0] if self._blocks else RowTable.empty()

    def _merge(self, t: RowTable) -> RowTable:
        if not np.all(t.frame[1:] > t.frame[:-1]):
            # by frame, then visible rows first, then in the file's order
            t = t.take(np.lexsort((np.arange(len(t)), t.visibility == 0, t.frame)))
        first = np.r_[True, t.frame[1:] != t.frame[:-1]]
        if first.all():
            return t
        again = np.flatnonzero(~first)  # rows on a frame seen before; compared with that frame's kept row
        starts = np.flatnonzero(first)
        kept = starts[np.searchsorted(starts, again, side="right") - 1]
        same_xy = np.all(np.isclose(t.xy[again], t.xy[kept], atol=1e-6), axis=1)
        visible = t.visibility[again] > 0
        clash = np.flatnonzero(visible & ((t.visibility[again] != t.visibility[kept]) | ~same_xy))
        if clash.size:
            i, j = int(again[clash[0]]), int(kept[clash[0]])
            raise FormatError(
                self.path,
                f"{self.wheres[t.source[i]]}: frame {int(t.frame[i])} has a second, different ball position "
                f"(the first is at {self.wheres[t.source[j]]})",
                fix="keep one ball track per frame: delete or split the overlapping track",
            )
        return t.take(first)

    def track(self) -> BallTrack:
        """The rows as a :class:`BallTrack` (sorted by frame)."""
        t = self.table()
        if not len(t):
            return BallTrack.empty()
        return BallTrack(t.frame, t.visibility, t.xy)


def check_frame(
    path: Path,
    frame: int,
    limit: int | None,
    *,
    where: str,
    line: int | None = None,
    shown: int | None = None,
    stated: str = "",
) -> None:
    """A clip frame must lie in ``0 .. limit - 1`` (``limit``: the file's length, else :data:`MAX_FRAMES`).

    Called on every frame number before anything is built from it, so a file naming frame 10^23 costs
    nothing. ``shown`` is the number as the file writes it; ``stated`` says what ``limit`` is
    ("the task's 30 frames"). The error names ``line`` when given (XML), else starts with ``where``.
    """
    if 0 <= frame < (limit if limit is not None else MAX_FRAMES):
        return
    prefix = "" if line is not None else f"{where}: "
    number = frame if shown is None else shown
    if frame < 0:
        problem = f"{prefix}frame {number} lies before the first frame"
        raise FormatError(path, problem, line=line, fix="check the frame number")
    past = stated
    if limit is None:
        past = f"frame {MAX_FRAMES} ({MAX_FRAMES_TEXT}), the most a file that states no length may address"
    raise FormatError(
        path,
        f"{prefix}frame {number} lies past {past}",
        line=line,
        fix="check the frame number, and that the file belongs to this video",
    )


def tighter(limit: int | None, stated: str, clip_frames: int | None) -> tuple[int | None, str]:
    """The file's frame limit, or the clip's length when that is known and smaller (with its words)."""
    if clip_frames is not None and (limit is None or clip_frames < limit):
        return clip_frames, f"the clip's {clip_frames} frames"
    return limit, stated


def add_keyframe_track(rows: Rows, keys: list[Key], *, last_frame: int | None, end_marker: bool) -> bool:
    """Spread one outside track over frames, the way the tool shows it, into ``rows``.

    A key gives a row at its frame. Between a key with ``carry_on`` and the next, ``xy`` is linear and
    the visibility is the earlier key's; between a hidden-after key and the next, the ball is not in
    the frame (visibility 0). After the last key there are no rows. With ``end_marker`` (CVAT), a final
    hidden key only closes the track, unless it lies on ``last_frame``, the clip's last frame.
    Frames must already be bounded (:func:`check_frame`): the rows between keys are built as arrays.

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
    if not keys:
        return False
    frame = np.array([k.frame for k in keys], np.int64)
    vis = np.array([k.visibility if k.xy is not None else 0 for k in keys], np.int8)
    xy = np.array([k.xy if k.xy is not None else (np.nan, np.nan) for k in keys], np.float64)
    carry = np.array([k.carry_on and k.xy is not None for k in keys])
    gap = np.append(np.diff(frame) - 1, 0)  # frames strictly between each key and the next
    # the place named for a key's row, and for the frames after it ("(interpolated)" or "(hidden)")
    own = np.array([rows.source(k.where) for k in keys], np.int32)
    after = own.copy()
    for j in np.flatnonzero(gap):
        after[j] = rows.source(f"{keys[j].where} ({'interpolated' if carry[j] else 'hidden'})")
    # one sorted block: each key's row, then the frames up to the next key
    counts = gap + 1
    step = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)  # 0 on a key
    on_key = step == 0
    nxt_xy = np.concatenate((xy[1:], xy[-1:]))
    delta = np.where(np.isnan(nxt_xy), 0.0, nxt_xy - xy)  # towards the next key (stay when it is hidden)
    row_xy = np.repeat(delta, counts, axis=0)
    row_xy *= (step / np.repeat(gap + 1, counts))[:, None]
    row_xy += np.repeat(xy, counts, axis=0)
    row_vis = np.where(on_key, np.repeat(vis, counts), np.repeat(np.where(carry, vis, 0), counts))
    row_src = np.where(on_key, np.repeat(own, counts), np.repeat(after, counts))
    end = len(step)
    if end_marker and len(keys) > 1 and keys[-1].xy is None and keys[-1].frame != last_frame:
        end -= 1  # the closing outside key ends the track: no row of its own
    rows.add(np.repeat(frame, counts)[:end] + step[:end], row_vis[:end], row_xy[:end], row_src[:end])
    last = keys[-1]
    return last.xy is not None and last.carry_on and last.frame != last_frame


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
def known_frames(clip: Clip) -> int | None:
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
        n_frames = known_frames(clip)
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
    if not clip.clip_yaml_path.is_file():
        clip.root.mkdir(parents=True, exist_ok=True)
        report.append(f"wrote {clip.write_info(info)}")
    for path, write, what in (
        (clip.ball_path, lambda t: write_ball_csv(t, imported.ball), f"{len(imported.ball)} rows"),
        (clip.events_path, lambda t: write_events_csv(t, imported.events), f"{len(imported.events)} events"),
    ):  # the one rule of the clip folder: a replaced file is backed up (.rally3d/backup/) and said so
        done = replace_keeping_backup(path, write, log=None)
        if done.backup is not None:
            report.append(f"backup {done.backup}")
        report.append(f"wrote {path} ({what})")
    return clip, report
