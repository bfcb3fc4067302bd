"""The labeler's UI-free state: the annotations of one clip, edits with undo/redo, interpolation, autosave.

One :class:`LabelSession` per browser tab. It holds four tables as dictionaries (normalised coordinates, as in
``docs/formats.md``)::

    ball      frame → (visibility, x, y)        ball.csv           (x, y NaN when visibility is 0)
    inactive  (frame, ball_no) → (x, y)         inactive_balls.csv
    events    frame → label                     events.csv
    points    name → (x, y)                     court_points.csv   (+ camera.yaml, calibrated live)

Every edit is a list of :class:`Change` rows (table, key, old, new; ``None`` = no row); it goes on the undo
stack and the touched tables are saved at once, atomically. Saving re-reads a file that changed on disk
since this session last saw it (another tab, another labeler process) and merges: the other writer's rows
are kept, this session's changed rows (tracked per row) are applied on top, and the session reports what it
merged and which rows both changed (this session's value wins there; undo brings the old one back).
A ``fcntl`` lock on ``<clip>/.label.lock`` serialises the read-merge-write of concurrent sessions.
"""
from __future__ import annotations

import fcntl
import math
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from inference.clipio import (
    BallTrack,
    Clip,
    CourtPoints,
    FormatError,
    HitEvents,
    InactiveBalls,
)
from inference.clipio.atomic import backup_file, remove_stale_temp_files

TABLES = ("ball", "inactive", "events", "points")
VISIBILITY_NAMES = {0: "out of frame", 1: "visible", 2: "hard to see", 3: "occluded"}
InterpMethod = Literal["linear", "physics"]
LOCK_NAME = ".label.lock"
DEFAULT_MAX_GAP_S = 0.5
"""Interpolation fills at most this long a gap between two keyframes (15 frames at 30 fps)."""
_LAST_WRITER: dict[tuple[str, str, Any], str] = {}
"""(clip folder, table, row key) → name of the session of this process that saved that row last."""


@dataclass(frozen=True)
class Change:
    """One row of one table: ``old`` → ``new`` (``None`` means the row is absent)."""

    table: str
    key: Any
    old: Any
    new: Any

    def __post_init__(self) -> None:
        if self.table not in TABLES:
            raise ValueError(f"unknown table {self.table!r}; tables: {TABLES}")


@dataclass
class Edit:
    """A named group of changes, undone and redone together."""

    label: str
    changes: list[Change]


@dataclass
class SaveReport:
    """What one save did: files written, rows taken over from another writer, rows both changed."""

    written: list[Path] = field(default_factory=list)
    merged_rows: int = 0
    conflicts: list[str] = field(default_factory=list)

    @property
    def message(self) -> str:
        parts = []
        if self.merged_rows:
            parts.append(f"merged {self.merged_rows} row(s) saved by another tab/session")
        if self.conflicts:
            shown = ", ".join(self.conflicts[:5]) + (" …" if len(self.conflicts) > 5 else "")
            parts.append(f"{len(self.conflicts)} row(s) were also changed elsewhere; kept this tab's: {shown}")
        return "; ".join(parts)


# --------------------------------------------------------------------------- table ⇄ dictionary codecs
Extra = dict[str, dict[Any, str]]
"""Unknown columns of a file: column → (row key → text); kept on every save."""


def _extra_of(obj, keys: list) -> Extra:
    return {c: dict(zip(keys, np.asarray(v, str).tolist())) for c, v in obj.extra.items()}


def _extra_for(extra: Extra | None, keys: list) -> dict[str, list[str]]:
    return {c: [vals.get(k, "") for k in keys] for c, vals in (extra or {}).items()}


def _ball_dict(track: BallTrack) -> dict[int, tuple[int, float, float]]:
    return {int(f): (int(v), float(x), float(y)) for f, v, (x, y) in zip(track.frame, track.visibility, track.xy)}


def _ball_track(rows: dict, extra: Extra | None = None) -> BallTrack:
    frames = sorted(rows)
    if not frames:
        return BallTrack.empty()
    vis = [rows[f][0] for f in frames]
    xy = [(math.nan, math.nan) if rows[f][0] == 0 else rows[f][1:] for f in frames]
    return BallTrack(frames, vis, np.asarray(xy, dtype=float), _extra_for(extra, frames))


def _inactive_dict(balls: InactiveBalls) -> dict[tuple[int, int], tuple[float, float]]:
    return {(int(f), int(b)): (float(x), float(y)) for f, b, (x, y) in zip(balls.frame, balls.ball_no, balls.xy)}


def _inactive_table(rows: dict, extra: Extra | None = None) -> InactiveBalls:
    keys = sorted(rows)
    if not keys:
        return InactiveBalls.empty()
    return InactiveBalls([k[0] for k in keys], [k[1] for k in keys], np.asarray([rows[k] for k in keys]),
                         _extra_for(extra, keys))


def _events_dict(events: HitEvents) -> dict[int, str]:
    return {int(f): str(e) for f, e in zip(events.frame, events.event)}


def _events_table(rows: dict, extra: Extra | None = None) -> HitEvents:
    frames = sorted(rows)
    return HitEvents(frames, [rows[f] for f in frames], _extra_for(extra, frames)) if frames else HitEvents.empty()


def _points_dict(points: CourtPoints) -> dict[str, tuple[float, float]]:
    return {n: (float(x), float(y)) for n, (x, y) in zip(points.names, points.xy)}


def _points_table(rows: dict, extra: Extra | None = None) -> CourtPoints:
    names = list(rows)
    if not names:
        return CourtPoints([], np.empty((0, 2)))
    return CourtPoints(names, np.array([rows[n] for n in names], float).reshape(-1, 2), _extra_for(extra, names))


def _same(a: Any, b: Any) -> bool:
    """Row equality where NaN equals NaN and floats match to the 7 decimals of the CSV files."""
    if a is None or b is None:
        return a is b
    if isinstance(a, str) or isinstance(b, str):
        return a == b
    ta, tb = (a if isinstance(a, tuple) else (a,)), (b if isinstance(b, tuple) else (b,))
    if len(ta) != len(tb):
        return False
    for x, y in zip(ta, tb):
        if isinstance(x, float) or isinstance(y, float):
            if math.isnan(x) and math.isnan(y):
                continue
            if math.isnan(x) or math.isnan(y) or abs(x - y) > 1e-6:
                return False
        elif x != y:
            return False
    return True


def _row_name(c: Change) -> str:
    """How a row is named to the annotator: ``ball @12``, ``event @30``, ``court point far_left`` …"""
    if c.table == "points":
        return f"court point {c.key}"
    if c.table == "inactive":
        return f"stationary ball {c.key[1]} @{c.key[0]}"
    return f"{'event' if c.table == 'events' else 'ball'} @{c.key}"


def _fingerprint(path: Path) -> tuple[int, int, int] | None:
    """(inode, mtime_ns, size) of a file, None when absent; atomic replaces always change the inode."""
    try:
        st = path.stat()
    except FileNotFoundError:
        return None
    return (st.st_ino, st.st_mtime_ns, st.st_size)


# ------------------------------------------------------------------------------------------- session
class LabelSession:
    """Annotations of one clip as one browser tab sees and edits them (UI-free; unit-tested).

    Args:
        clip: the clip folder (``clip.yaml`` and frames must exist; the CSV files may be missing).
        court: the court model (for court points, event vocabulary and live calibration); default: the
            clip's court YAML.
        autosave: save the touched tables after every edit (the labeler always does; tests may turn it off).
        skip_bad_rows: open a file with bad rows anyway, leaving those rows out (:attr:`skipped` lists them);
            the file is not touched until an edit saves it, and then its original is first copied to
            ``.rally3d/backup/``. Without it a bad row raises :class:`FormatError`.
        name: how other tabs name this one in their messages (e.g. "tab 2").

    Attributes:
        max_gap: interpolation never fills more than this many frames between two keyframes.
    """

    def __init__(self, clip: Clip | str | Path, court=None, *, autosave: bool = True, skip_bad_rows: bool = False,
                 name: str = "another tab"):
        self.clip = clip if isinstance(clip, Clip) else Clip(clip)
        info = self.clip.info
        self.width, self.height, self.fps = info.width, info.height, info.fps
        self.n_frames = int(self.clip.n_frames)
        if court is None:
            from inference.court import load_court

            court = load_court(self.clip.court_path())
        self.court = court
        self.autosave = autosave
        self.name = name
        self.skip_bad_rows = skip_bad_rows
        self.skipped: dict[str, list[FormatError]] = {t: [] for t in TABLES}
        self.max_gap = max(2, int(round(DEFAULT_MAX_GAP_S * self.fps)))
        self.frame = 0
        self.undo_stack: list[Edit] = []
        self.redo_stack: list[Edit] = []
        self.ball_proposals: dict[int, tuple[int, float, float]] = {}
        self.ball_proposal_source: str = ""
        self.event_proposals: dict[int, str] = {}
        self.ball_scores: dict[int, float] = {}  # frame → the detector's confidence (0..1) of its proposal
        self.interpolation_skipped: list[tuple[int, int, str]] = []  # (keyframe, keyframe, why) of the last run
        self.notices: list[str] = []
        self.calibration = None  # inference.camera.calibration.CalibrationResult of the current points
        self.calibration_error: str = ""
        self.tables: dict[str, dict] = {t: {} for t in TABLES}
        self._base: dict[str, dict] = {t: {} for t in TABLES}
        self._dirty: dict[str, set] = {t: set() for t in TABLES}
        self._seen: dict[str, tuple | None] = {t: None for t in TABLES}
        self._extra: dict[str, Extra] = {t: {} for t in TABLES}
        self._listeners: list[Callable[[LabelSession], None]] = []
        for table in TABLES:
            self._load(table)
        self._recalibrate(write=False)
        with self._locked():
            litter = remove_stale_temp_files(self.clip.root)
        if litter:
            self.notices.append(f"removed {len(litter)} temporary file(s) left by a save that did not finish: "
                                + ", ".join(p.name for p in litter[:3]))

    # ------------------------------------------------------------------------------- tables & files
    @property
    def ball(self) -> dict[int, tuple[int, float, float]]:
        return self.tables["ball"]

    @property
    def inactive(self) -> dict[tuple[int, int], tuple[float, float]]:
        return self.tables["inactive"]

    @property
    def events(self) -> dict[int, str]:
        return self.tables["events"]

    @property
    def points(self) -> dict[str, tuple[float, float]]:
        return self.tables["points"]

    def path(self, table: str) -> Path:
        return {"ball": self.clip.ball_path, "inactive": self.clip.inactive_balls_path,
                "events": self.clip.events_path, "points": self.clip.court_points_path}[table]

    def _read_disk(self, table: str) -> dict:
        """The rows of ``table``'s file (bad rows left out when :attr:`skip_bad_rows`); remembers its extra columns."""
        clip, n = self.clip, self.n_frames
        skipped: list[FormatError] | None = [] if self.skip_bad_rows else None
        if table == "ball":
            obj = clip.read_ball(missing_ok=True, n_frames=n, skipped=skipped)
            rows = _ball_dict(obj)
        elif table == "inactive":
            obj = clip.read_inactive_balls(missing_ok=True, n_frames=n, skipped=skipped)
            rows = _inactive_dict(obj)
        elif table == "events":
            obj = clip.read_events(missing_ok=True, n_frames=n, labels=self.event_labels, skipped=skipped)
            rows = _events_dict(obj)
        else:
            obj = clip.read_court_points(known_names=self.court.point_names, missing_ok=True, skipped=skipped)
            rows = _points_dict(obj)
        self._extra[table] = _extra_of(obj, list(rows))
        if skipped is not None:
            self.skipped[table] = skipped
        return rows

    def _write_disk(self, table: str, rows: dict) -> Path:
        clip, extra = self.clip, self._extra[table]
        if self.skipped[table] and self.path(table).is_file():  # keep the bad rows' original before replacing
            copy = backup_file(self.path(table), self.clip.root / ".rally3d" / "backup")
            self.notices.append(f"{self.path(table).name} had {len(self.skipped[table])} bad row(s), left out; "
                                f"its original is kept in {copy}")
            self.skipped[table] = []
        if table == "ball":
            return clip.write_ball(_ball_track(rows, extra))
        if table == "inactive":
            return clip.write_inactive_balls(_inactive_table(rows, extra))
        if table == "events":
            return clip.write_events(_events_table(rows, extra))
        return clip.write_court_points(_points_table(rows, extra))

    def _load(self, table: str) -> None:
        fp = _fingerprint(self.path(table))
        rows = self._read_disk(table)
        self.tables[table] = dict(rows)
        self._base[table] = dict(rows)
        self._seen[table] = fp
        self._dirty[table].clear()

    @contextmanager
    def _locked(self) -> Iterator[None]:
        """Exclusive lock of the clip folder for a read-merge-write (other sessions and processes wait)."""
        with open(self.clip.root / LOCK_NAME, "a") as f:
            fcntl.flock(f.fileno(), fcntl.LOCK_EX)
            try:
                yield
            finally:
                fcntl.flock(f.fileno(), fcntl.LOCK_UN)

    def _merge_from_disk(self, table: str, report: SaveReport) -> None:
        """Take the file's rows as the new base and re-apply this session's dirty rows on top."""
        disk = self._read_disk(table)
        base, mine = self._base[table], self.tables[table]
        merged = dict(disk)
        for key in self._dirty[table]:
            theirs_changed = not _same(disk.get(key), base.get(key))
            if theirs_changed and not _same(disk.get(key), mine.get(key)):
                report.conflicts.append(f"{table}:{key}")
            if key in mine:
                merged[key] = mine[key]
            else:
                merged.pop(key, None)
        report.merged_rows += sum(
            1 for key in set(disk) | set(base) if key not in self._dirty[table] and not _same(disk.get(key), base.get(key))
        )
        self._base[table] = disk
        self.tables[table] = merged

    def save(self, tables: Iterable[str] = TABLES) -> SaveReport:
        """Write the given tables (merging other writers' changes first); camera.yaml follows court points."""
        report = SaveReport()
        with self._locked():
            for table in tables:
                if self._seen[table] != _fingerprint(self.path(table)):
                    self._merge_from_disk(table, report)
                if not self._dirty[table] and self.path(table).exists():
                    continue
                path = self._write_disk(table, self.tables[table])
                report.written.append(path)
                root = str(self.clip.root.resolve())
                for key in self._dirty[table]:
                    _LAST_WRITER[(root, table, key)] = self.name
                self._base[table] = dict(self.tables[table])
                self._dirty[table].clear()
                self._seen[table] = _fingerprint(path)
                if table == "points":
                    self._recalibrate(write=True)
        if report.message:
            self.notices.append(report.message)
        return report

    def sync(self) -> SaveReport:
        """Pick up rows that other sessions saved since this one last read or wrote (no write)."""
        report = SaveReport()
        changed = [t for t in TABLES if self._seen[t] != _fingerprint(self.path(t))]
        if not changed:
            return report
        with self._locked():
            for table in changed:
                fp = _fingerprint(self.path(table))
                self._merge_from_disk(table, report)
                self._seen[table] = fp
                if table == "points":
                    self._recalibrate(write=False)
        if report.merged_rows:
            self.notices.append(f"loaded {report.merged_rows} row(s) saved by another tab/session")
            self._notify()
        return report

    def reload(self) -> None:
        """Drop unsaved state and re-read every file (undo history is kept only for saved edits' sake)."""
        for table in TABLES:
            self._load(table)
        self._recalibrate(write=False)
        self._notify()

    # ------------------------------------------------------------------------------ edits, undo/redo
    def on_change(self, callback: Callable[[LabelSession], None]) -> None:
        """Call ``callback(session)`` after every edit, undo, redo and merge."""
        self._listeners.append(callback)

    def _notify(self) -> None:
        for cb in list(self._listeners):
            cb(self)

    def _set(self, table: str, key, value) -> None:
        rows = self.tables[table]
        if value is None:
            rows.pop(key, None)
        else:
            rows[key] = value
        self._dirty[table].add(key)

    def apply(self, label: str, changes: list[Change]) -> Edit | None:
        """Apply ``changes`` as one undoable edit and autosave; no-op changes are dropped.

        Rows another writer saved meanwhile are read first, so ``old`` (what undo brings back) is what the
        file held, not this session's older view.
        """
        if self.autosave:
            self.sync()
            changes = [Change(c.table, c.key, self.tables[c.table].get(c.key), c.new) for c in changes]
        changes = [c for c in changes if not _same(c.old, c.new)]
        if not changes:
            return None
        for c in changes:
            self._set(c.table, c.key, c.new)
        edit = Edit(label, changes)
        self.undo_stack.append(edit)
        self.redo_stack.clear()
        self._after_edit(changes)
        return edit

    def _after_edit(self, changes: list[Change]) -> None:
        touched = sorted({c.table for c in changes}, key=TABLES.index)
        if self.autosave:
            self.save(touched)
        elif "points" in touched:
            self._recalibrate(write=False)
        self._notify()

    def undo(self) -> Edit | None:
        """Revert the last edit (and save); None when there is nothing to undo.

        Only rows that still hold what this session wrote are reverted: a row another tab or labeler changed
        since is left as they made it, and :attr:`notices` says which rows and who changed them.
        """
        return self._replay(self.undo_stack, self.redo_stack, undo=True)

    def redo(self) -> Edit | None:
        """Re-apply the last undone edit (and save); rows changed elsewhere since are left alone (as in undo)."""
        return self._replay(self.redo_stack, self.undo_stack, undo=False)

    def _replay(self, source: list[Edit], target: list[Edit], *, undo: bool) -> Edit | None:
        if not source:
            return None
        self.sync()  # see what other writers did to these rows since
        edit = source.pop()
        mine, theirs = [], []
        for c in edit.changes:
            expected = c.new if undo else c.old
            (mine if _same(self.tables[c.table].get(c.key), expected) else theirs).append(c)
        for c in reversed(mine) if undo else mine:
            self._set(c.table, c.key, c.old if undo else c.new)
        if theirs:
            shown = ", ".join(f"{_row_name(c)} (by {self._last_writer(c)})" for c in theirs[:4])
            more = f" and {len(theirs) - 4} more" if len(theirs) > 4 else ""
            self.notices.append(f"{'undo' if undo else 'redo'} of '{edit.label}' left {len(theirs)} row(s) as "
                                f"changed since: {shown}{more}")
        if not mine:
            self._notify()
            return Edit(edit.label, [])
        done = Edit(edit.label, mine)
        target.append(done)
        self._after_edit(mine)
        return done

    def _last_writer(self, change: Change) -> str:
        return _LAST_WRITER.get((str(self.clip.root.resolve()), change.table, change.key),
                                "another labeler or a hand edit")

    def _change(self, table: str, key, new) -> Change:
        return Change(table, key, self.tables[table].get(key), new)

    # ---------------------------------------------------------------------------------------- checks
    def _check_frame(self, frame: int) -> int:
        frame = int(frame)
        if not 0 <= frame < self.n_frames:
            raise ValueError(f"frame {frame} is outside the clip (0..{self.n_frames - 1})")
        return frame

    def _check_xy(self, xy) -> tuple[float, float]:
        x, y = (float(v) for v in xy)
        if not (math.isfinite(x) and math.isfinite(y)) or not (0 <= x <= 1 and 0 <= y <= 1):
            raise ValueError(f"position {xy} must be normalised image coordinates in [0, 1]")
        return (x, y)

    def to_norm(self, x_px: float, y_px: float) -> tuple[float, float]:
        """Pixels → normalised image coordinates, clipped to the image."""
        return (min(max(x_px / self.width, 0.0), 1.0), min(max(y_px / self.height, 0.0), 1.0))

    # ------------------------------------------------------------------------------------------ ball
    def set_ball(self, frame: int, xy, visibility: int = 1) -> None:
        """Ball at normalised ``xy`` on ``frame`` with visibility 1 (visible), 2 (hard to see) or 3 (occluded)."""
        frame = self._check_frame(frame)
        if visibility not in (1, 2, 3):
            raise ValueError(f"a ball position needs visibility 1, 2 or 3, got {visibility}")
        x, y = self._check_xy(xy)
        self.apply(f"ball {VISIBILITY_NAMES[visibility]} @{frame}", [self._change("ball", frame, (visibility, x, y))])
        self.ball_proposals.pop(frame, None)

    def set_visibility(self, frame: int, visibility: int) -> bool:
        """Change the visibility of ``frame``'s ball; 0 (out of frame) drops the position.

        Returns False (nothing done) when 1–3 is asked for a frame without a position (click the ball then).
        """
        frame = self._check_frame(frame)
        if visibility not in VISIBILITY_NAMES:
            raise ValueError(f"visibility must be one of {sorted(VISIBILITY_NAMES)}, got {visibility}")
        row = self.ball.get(frame)
        if visibility == 0:
            new = (0, math.nan, math.nan)
        elif row is None or row[0] == 0:
            return False
        else:
            new = (visibility, row[1], row[2])
        self.apply(f"ball {VISIBILITY_NAMES[visibility]} @{frame}", [self._change("ball", frame, new)])
        self.ball_proposals.pop(frame, None)
        return True

    def clear_ball(self, frame: int) -> None:
        """Remove ``frame``'s ball row (the frame becomes "not labelled")."""
        frame = self._check_frame(frame)
        self.apply(f"clear ball @{frame}", [self._change("ball", frame, None)])

    def keyframes(self) -> list[int]:
        """Frames with a ball position (visibility 1–3), sorted."""
        return sorted(f for f, row in self.ball.items() if row[0] > 0)

    def next_unlabelled(self, frame: int) -> int | None:
        """First frame after ``frame`` without a ball row (wrapping around), None when all are labelled."""
        for k in range(1, self.n_frames + 1):
            f = (frame + k) % self.n_frames
            if f not in self.ball:
                return f
        return None

    def trail(self, frame: int, length: int = 15) -> np.ndarray:
        """``(K, 3)`` rows ``(frame, x, y)`` of the ball positions in ``[frame - length, frame]``, in order."""
        rows = [(f, *self.ball[f][1:]) for f in range(max(0, frame - length), frame + 1)
                if f in self.ball and self.ball[f][0] > 0]
        return np.asarray(rows, dtype=float).reshape(-1, 3)

    # --------------------------------------------------------------------------------- interpolation
    def flight(self, frame: int) -> tuple[int, int]:
        """``(first, last)`` frame of the flight holding ``frame``: from the event at or before it to the next one.

        The clip's ends count as bounds. A frame with an event starts a flight (the contact is its first frame).
        """
        lo = max((e for e in self.events if e <= frame), default=0)
        hi = min((e for e in self.events if e > frame), default=self.n_frames - 1)
        return lo, hi

    def interpolate(self, method: InterpMethod = "physics", start: int = 0, stop: int | None = None,
                    max_gap: int | None = None) -> int:
        """Propose ball positions for the unlabelled frames between two keyframes of one flight.

        A gap is filled only when no event lies strictly between its two keyframes (a hit or bounce changes
        the path) and the keyframes are at most ``max_gap`` frames apart (default :attr:`max_gap`): a long
        gap is not guessed. ``physics`` fits a parabola in time (gravity under perspective, x and y each
        quadratic) through up to two more keyframes of the same flight on each side, corrected to pass through
        both keyframes exactly; with fewer than 3 keyframes in the flight it is a straight line, as is
        ``linear``. Filled rows are visibility 1 (visible) and provisional (:attr:`ball_proposals`) until
        accepted. Returns their number.
        """
        if method not in ("linear", "physics"):
            raise ValueError(f"unknown interpolation {method!r}; choose linear or physics")
        max_gap = self.max_gap if max_gap is None else int(max_gap)
        stop = self.n_frames - 1 if stop is None else min(int(stop), self.n_frames - 1)
        keys = self.keyframes()
        proposals: dict[int, tuple[int, float, float]] = {}
        self.interpolation_skipped = []
        for a, b in zip(keys[:-1], keys[1:]):
            gap = [f for f in range(a + 1, b) if start <= f <= stop and f not in self.ball]
            if not gap:
                continue
            crossing = [e for e in self.events if a < e < b]
            if crossing or b - a > max_gap:
                self.interpolation_skipped.append(
                    (a, b, f"event @{crossing[0]}" if crossing else f"{b - a} frames apart (max {max_gap})"))
                continue
            xy = self._gap_positions(a, b, gap, keys, method)
            for f, (x, y) in zip(gap, np.clip(xy, 0.0, 1.0)):
                proposals[f] = (1, float(x), float(y))
        self.ball_proposals = proposals
        self.ball_proposal_source = f"interpolation ({method})"
        self._notify()
        return len(proposals)

    def _gap_positions(self, a: int, b: int, gap: list[int], keys: list[int], method: str) -> np.ndarray:
        """``(len(gap), 2)`` positions between keyframes ``a`` and ``b`` (one flight)."""
        pa, pb = np.asarray(self.ball[a][1:]), np.asarray(self.ball[b][1:])
        t = np.asarray(gap, float)
        line = pa[None] + ((t - a) / (b - a))[:, None] * (pb - pa)[None]
        if method == "linear":
            return line
        lo, hi = self.flight(a)
        before = [k for k in keys if lo <= k < a][-2:]
        after = [k for k in keys if b < k <= hi][:2]
        support = [*before, a, b, *after]
        if len(support) < 3:
            return line
        ts = np.asarray(support, float)
        pts = np.asarray([self.ball[k][1:] for k in support])
        fit = np.stack([np.polyval(np.polyfit(ts, pts[:, i], 2), t) for i in range(2)], axis=1)
        ends = np.stack([np.polyval(np.polyfit(ts, pts[:, i], 2), [a, b]) for i in range(2)], axis=1)
        # a straight correction makes the curve meet both keyframes exactly
        err_a, err_b = pa - ends[0], pb - ends[1]
        return fit + err_a[None] + ((t - a) / (b - a))[:, None] * (err_b - err_a)[None]

    def set_ball_proposals(self, track: BallTrack, source: str, scores: np.ndarray | None = None) -> int:
        """Show a model's track (e.g. the ball detector's) as proposals; returns how many frames it covers.

        ``scores``: ``(n_frames,)`` the model's confidence in ``[0, 1]`` per frame (0 where it found nothing);
        it colours the proposals and drives :meth:`next_uncertain`.
        """
        self.ball_proposals = _ball_dict(track)
        self.ball_proposals = {f: r for f, r in self.ball_proposals.items() if 0 <= f < self.n_frames}
        self.ball_scores = {} if scores is None else {
            f: float(v) for f, v in enumerate(np.clip(np.asarray(scores, float), 0, 1)[: self.n_frames])}
        self.ball_proposal_source = source
        self._notify()
        return len(self.ball_proposals)

    def accept_ball_proposals(self, frames: Iterable[int] | None = None, *, overwrite: bool = False) -> int:
        """Turn proposals into ball rows (all, or those at ``frames``); labelled frames only if ``overwrite``."""
        wanted = sorted(self.ball_proposals if frames is None else (f for f in frames if f in self.ball_proposals))
        changes = [self._change("ball", f, self.ball_proposals[f]) for f in wanted
                   if overwrite or f not in self.ball]
        for f in wanted:
            self.ball_proposals.pop(f, None)
        self.apply(f"accept {len(changes)} ball proposal(s)", changes)
        self._notify()
        return len(changes)

    def accept_flight_proposals(self, frame: int) -> tuple[int, tuple[int, int]]:
        """Accept the proposals of the flight holding ``frame`` (it stops at the events on both sides).

        Returns the number accepted and the flight's ``(first, last)`` frame.
        """
        lo, hi = self.flight(self._check_frame(frame))
        return self.accept_ball_proposals(range(lo, hi + 1)), (lo, hi)

    def next_uncertain(self, frame: int, threshold: float = 0.5) -> int | None:
        """The next frame after ``frame`` (wrapping) that is not labelled and where the detector was unsure:
        its confidence is below ``threshold`` (0 where it found no ball). None without detector scores."""
        if not self.ball_scores:
            return None
        for k in range(1, self.n_frames + 1):
            f = (frame + k) % self.n_frames
            if f not in self.ball and self.ball_scores.get(f, 0.0) < threshold:
                return f
        return None

    def reject_ball_proposals(self, frames: Iterable[int] | None = None) -> int:
        """Drop proposals (all, or those at ``frames``)."""
        drop = list(self.ball_proposals) if frames is None else [f for f in frames if f in self.ball_proposals]
        for f in drop:
            self.ball_proposals.pop(f)
        self._notify()
        return len(drop)

    # -------------------------------------------------------------------------------- inactive balls
    def inactive_at(self, frame: int) -> dict[int, tuple[float, float]]:
        """``ball_no → (x, y)`` of the stationary balls on ``frame``."""
        return {b: xy for (f, b), xy in self.inactive.items() if f == frame}

    def _run(self, frame: int, ball_no: int) -> list[int]:
        """Frames ``frame, frame+1, …`` on which ``ball_no`` is present without a gap."""
        out, f = [], frame
        while (f, ball_no) in self.inactive:
            out.append(f)
            f += 1
        return out

    def add_inactive(self, frame: int, xy) -> int:
        """A new stationary ball at ``xy`` from ``frame`` on (carried to the end of the clip); returns its number."""
        frame = self._check_frame(frame)
        x, y = self._check_xy(xy)
        ball_no = 1 + max((b for _, b in self.inactive), default=-1)
        changes = [self._change("inactive", (f, ball_no), (x, y)) for f in range(frame, self.n_frames)]
        self.apply(f"add stationary ball {ball_no} @{frame}", changes)
        return ball_no

    def move_inactive(self, frame: int, ball_no: int, xy) -> None:
        """Move stationary ball ``ball_no`` to ``xy`` on ``frame`` and the following frames it is carried to."""
        frame = self._check_frame(frame)
        x, y = self._check_xy(xy)
        run = self._run(frame, ball_no)
        if not run:
            raise KeyError(f"no stationary ball {ball_no} on frame {frame}")
        self.apply(f"move stationary ball {ball_no} @{frame}",
                   [self._change("inactive", (f, ball_no), (x, y)) for f in run])

    def remove_inactive(self, frame: int, ball_no: int) -> None:
        """Remove stationary ball ``ball_no`` from ``frame`` on (it stays on earlier frames)."""
        run = self._run(self._check_frame(frame), ball_no)
        if not run:
            raise KeyError(f"no stationary ball {ball_no} on frame {frame}")
        self.apply(f"remove stationary ball {ball_no} @{frame}",
                   [self._change("inactive", (f, ball_no), None) for f in run])

    def nearest_inactive(self, frame: int, xy, max_dist_px: float = 20.0) -> int | None:
        """The stationary ball of ``frame`` nearest to ``xy`` within ``max_dist_px``, or None."""
        best, best_d = None, max_dist_px
        for b, (x, y) in self.inactive_at(frame).items():
            d = math.hypot((x - xy[0]) * self.width, (y - xy[1]) * self.height)
            if d <= best_d:
                best, best_d = b, d
        return best

    # ---------------------------------------------------------------------------------------- events
    @property
    def event_labels(self) -> list[str]:
        """The fine-grained event vocabulary of this clip's court: its surfaces, then the players."""
        return self.court.annotation_labels

    def set_event(self, frame: int, label: str | None) -> None:
        """Set (or with ``None`` remove) the event of ``frame``."""
        frame = self._check_frame(frame)
        if label is not None and label not in self.event_labels:
            raise ValueError(f"unknown event {label!r} for {self.court.name}; valid: {', '.join(self.event_labels)}")
        self.apply(f"event {label or 'removed'} @{frame}", [self._change("events", frame, label)])

    def toggle_event(self, frame: int, label: str) -> None:
        """Set ``label`` on ``frame``, or remove it when the frame already has exactly that event."""
        self.set_event(frame, None if self.events.get(int(frame)) == label else label)

    def next_event(self, frame: int, direction: int = 1) -> int | None:
        """The nearest event frame after (``direction=1``) or before (``-1``) ``frame``."""
        frames = sorted(self.events)
        cands = [f for f in frames if (f > frame if direction > 0 else f < frame)]
        if not cands:
            return None
        return cands[0] if direction > 0 else cands[-1]

    def set_event_proposals(self, events: HitEvents) -> int:
        self.event_proposals = {f: e for f, e in _events_dict(events).items() if 0 <= f < self.n_frames}
        self._notify()
        return len(self.event_proposals)

    def accept_event_proposals(self, frames: Iterable[int] | None = None, *, overwrite: bool = False) -> int:
        wanted = sorted(self.event_proposals if frames is None else (f for f in frames if f in self.event_proposals))
        changes = [self._change("events", f, self.event_proposals[f]) for f in wanted
                   if (overwrite or f not in self.events) and self.event_proposals[f] in self.event_labels]
        for f in wanted:
            self.event_proposals.pop(f, None)
        self.apply(f"accept {len(changes)} event proposal(s)", changes)
        self._notify()
        return len(changes)

    # ---------------------------------------------------------------------------- court points, camera
    def set_point(self, name: str, xy) -> None:
        """Place court point ``name`` at normalised ``xy``; recalibrates live once ≥ 6 points (floor points suffice) exist."""
        if name not in self.court.points:
            raise KeyError(f"unknown court point {name!r} for {self.court.name}; valid: {', '.join(self.court.points)}")
        self.apply(f"court point {name}", [self._change("points", name, self._check_xy(xy))])

    def remove_point(self, name: str) -> None:
        self.apply(f"remove court point {name}", [self._change("points", name, None)])

    def expected_points_px(self) -> dict[str, np.ndarray]:
        """Where the court points should be in the image, in pixels, as far as the clicks so far tell.

        Through the live calibration when there is one; else, from 4 clicked floor points on, through the
        floor's homography (floor points only). Points that cannot be placed yet are left out.
        """
        court = self.court
        if self.calibration is not None:
            cam = self.calibration.camera
            names = court.point_names
            px = cam.project(court.point_array(names))
            return {n: p for n, p in zip(names, px) if np.isfinite(p).all()}
        ground = [n for n in self.points if abs(court.points[n][2]) < 1e-6]
        if len(ground) < 4:
            return {}
        import cv2

        src = np.array([court.points[n][:2] for n in ground], np.float64)
        dst = np.array([self.points[n] for n in ground], np.float64) * [self.width, self.height]
        H, _ = cv2.findHomography(src, dst, 0)
        if H is None:
            return {}
        out = {}
        for n in court.point_names:
            x, y, z = court.points[n]
            if abs(z) < 1e-6:
                q = H @ np.array([x, y, 1.0])
                if q[2] > 1e-9:
                    out[n] = q[:2] / q[2]
        return out

    def offered_points(self, margin: float = 0.02) -> list[str]:
        """The court points the point dropdown offers, in the court's order: every point clicked (to move or
        remove it) and the others unless the clicks so far put them outside the picture (beyond ``margin`` ×
        its size) or, calibrated, behind the camera; every point while nothing is known yet."""
        names = self.court.point_names
        expected = self.expected_points_px()
        if not expected:
            return list(names)
        mx, my = margin * self.width, margin * self.height

        def offered(n: str) -> bool:
            if n in self.points:
                return True
            if n not in expected:                # behind the camera, or not on the floor's homography
                return self.calibration is None
            x, y = expected[n]
            return bool(-mx <= x <= self.width + mx and -my <= y <= self.height + my)

        return [n for n in names if offered(n)]

    def next_point(self, after: str | None = None, view_px: tuple[float, float, float, float] | None = None,
                   ) -> str | None:
        """The court point to click next: the first unplaced one (in the court's order, after ``after``)
        that is expected inside ``view_px`` = ``(x0, y0, x1, y1)`` (default the whole image); points whose
        place is not known yet come next, then the rest. None when every point is placed."""
        names = self.court.point_names
        start = names.index(after) + 1 if after in names else 0
        offered = set(self.offered_points())
        order = [n for n in names[start:] + names[:start] if n not in self.points and n in offered]
        if not order:
            return None
        x0, y0, x1, y1 = view_px or (0.0, 0.0, float(self.width), float(self.height))
        x0, y0, x1, y1 = max(x0, 0.0), max(y0, 0.0), min(x1, self.width), min(y1, self.height)
        expected = self.expected_points_px()
        inside = [n for n in order if n in expected and x0 <= expected[n][0] <= x1 and y0 <= expected[n][1] <= y1]
        unknown = [n for n in order if n not in expected]
        return (inside or unknown or order)[0]

    def _recalibrate(self, *, write: bool) -> None:
        """Calibrate from the current points; write camera.yaml on success (when ``write``)."""
        from inference.camera.calibration import CalibrationError, calibrate_court

        self.calibration, self.calibration_error = None, ""
        if not self.points:
            self.calibration_error = "no court points yet"
            return
        size = np.array([self.width, self.height], float)
        image_points = {n: np.asarray(xy) * size for n, xy in self.points.items()}
        try:
            result = calibrate_court(self.court, image_points, (self.width, self.height))
        except CalibrationError as e:
            self.calibration_error = str(e)
            return
        self.calibration = result
        if write:
            self.clip.write_camera(result.camera)

    # --------------------------------------------------------------------------------------- summary
    def summary(self) -> dict[str, Any]:
        """Counts for the GUI: labelled frames, keyframes, events, stationary balls, court points, proposals."""
        return {
            "frames": self.n_frames,
            "labelled": len(self.ball),
            "labelled_pct": 100.0 * len(self.ball) / max(self.n_frames, 1),
            "visible": sum(1 for r in self.ball.values() if r[0] > 0),
            "events": len(self.events),
            "inactive_balls": len({b for _, b in self.inactive}),
            "court_points": len(self.points),
            "ball_proposals": len(self.ball_proposals),
            "event_proposals": len(self.event_proposals),
            "rms_px": None if self.calibration is None else self.calibration.rms_px,
        }


def clip_overview(clip: Clip) -> dict[str, Any]:
    """Labelled %, events and court points of a clip, read from its files (for the dataset overview)."""
    try:
        n = int(clip.n_frames)
        ball = clip.read_ball(missing_ok=True, n_frames=n)
        events = clip.read_events(missing_ok=True, n_frames=n)
        points = clip.read_court_points(missing_ok=True)
    except (FormatError, ValueError, OSError) as e:
        return {"clip": clip.root.name, "error": str(e)}
    return {"clip": clip.root.name, "sport": clip.info.sport, "frames": n, "labelled": len(ball),
            "labelled_pct": 100.0 * len(ball) / max(n, 1), "events": len(events), "court_points": len(points),
            "camera": clip.camera_path.is_file()}


def find_clips(path: str | Path) -> list[Clip]:
    """The clips of ``path``: the clip itself, a dataset's manifest.yaml entries, or clip sub-folders."""
    from inference.clipio import Manifest

    root = Path(path)
    if (root / "clip.yaml").is_file():
        return [Clip(root)]
    if (root / "manifest.yaml").is_file():
        return [Clip(p) for p in Manifest.load(root / "manifest.yaml").paths()]
    if root.is_dir():
        clips = [Clip(p.parent) for p in sorted(root.glob("*/clip.yaml"))]
        if clips:
            return clips
    raise FileNotFoundError(f"{root} is neither a clip folder (with clip.yaml) nor a dataset "
                            "(manifest.yaml or clip sub-folders); pass a clip or dataset folder")


__all__ = ["Change", "Edit", "LabelSession", "SaveReport", "clip_overview", "find_clips"]
