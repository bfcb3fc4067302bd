"""Shots of a broadcast clip: where the editor cut (replays, close-ups, crowd) and which shots show the court.

1. **Cuts.** Every frame is shrunk to a 48×27 colour thumbnail; the mean absolute difference between
   consecutive thumbnails jumps at a cut. A frame starts a new shot when its difference is above
   :data:`CUT_MIN` grey levels *and* :data:`CUT_RATIO` × the median difference of the frames around it
   (a moving camera or players raise the baseline, not the jump). Shots shorter than :data:`MIN_SHOT_S`
   (the frames of a wipe or a dissolve) are kept as shots of their own.
2. **Court view or not.** With a camera (``camera.yaml``), a shot shows the court when the calibrated
   court lines, shifted by up to ±24 px for drift, fall on painted-line pixels in its frames (the median
   support over three of its frames, :func:`inference.courtfit.drift.frame_shift`, at least
   :data:`SUPPORT_MIN` and at least :data:`SUPPORT_OF_BEST` × the best shot's: another court's lines
   meet a few of ours by chance, a tennis court under a padel camera scores ~0.3). Without a
   camera — or when no shot passes — the longest shot is the main view and a shot shows the court when
   its mean thumbnail is within :data:`SIMILAR_MAX` grey levels of the main view's.

A clip with one shot is a court view whatever the scores say (the user chose it). ``rally3d infer``
writes the result as ``shots.json`` (docs/formats.md) and runs the ball detector on court-view frames only;
the other frames are reported as unseen (visibility 0). The hit-event model and the 3D fit then run on
each court-view shot on its own (:mod:`inference.pipeline.per_shot`): no event window, no flight joins frames
across a cut.

Example:
    >>> report = find_shots(clip, camera, court)
    >>> report.active()            # (N,) bool, court-view frames
    >>> print(report.table())
"""
from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

THUMB = (48, 27)
CUT_MIN = 12.0
CUT_RATIO = 4.0
MIN_SHOT_S = 0.2
SUPPORT_MIN = 0.3
SUPPORT_OF_BEST = 0.6
SIMILAR_MAX = 14.0
SHOTS_VERSION = 1


@dataclass
class Shot:
    """Frames ``start .. stop-1`` between two cuts.

    Attributes:
        court_view: the shot shows the court from the calibrated (main) camera.
        score: court-line support (0–1, ``how == "court lines"``) or mean thumbnail difference to the main
            view (grey levels, ``how == "similarity"``).
    """

    start: int
    stop: int
    court_view: bool
    score: float
    how: str

    @property
    def n_frames(self) -> int:
        return self.stop - self.start


@dataclass
class ShotReport:
    """The shots of a clip, in order, covering frames ``0 .. n_frames-1``."""

    shots: list[Shot]
    n_frames: int
    fps: float
    notes: list[str] = field(default_factory=list)

    def active(self) -> np.ndarray:
        """(n_frames,) bool: frames of court-view shots."""
        out = np.zeros(self.n_frames, bool)
        for s in self.shots:
            out[s.start:s.stop] = s.court_view
        return out

    def court_spans(self) -> list[tuple[int, int]]:
        """``[(start, stop), ...]`` of the court-view shots, in order; two court views either side of a cut
        stay apart (the time across a cut is not continuous)."""
        return [(s.start, s.stop) for s in self.shots if s.court_view]

    def summary(self) -> str:
        court = [s for s in self.shots if s.court_view]
        left = self.n_frames - sum(s.n_frames for s in court)
        text = f"{len(self.shots)} shot{'s' if len(self.shots) != 1 else ''}, {len(court)} court view"
        if left:
            text += (f"; {left} frames outside court views left out (frames " +
                     ", ".join(f"{s.start}–{s.stop - 1}" for s in self.shots if not s.court_view) + ")")
        return text + "".join(f"; {n}" for n in self.notes)

    def table(self) -> str:
        lines = ["shot  frames          seconds        court view  score  by"]
        for k, s in enumerate(self.shots):
            lines.append(f"{k:4d}  {s.start:6d}–{s.stop - 1:<6d}  {s.start / self.fps:6.2f}–{s.stop / self.fps:<6.2f}  "
                         f"{'yes' if s.court_view else 'no':<10}  {s.score:5.2f}  {s.how}")
        return "\n".join(lines + [self.summary()])

    def to_dict(self) -> dict:
        return {"version": SHOTS_VERSION, "n_frames": self.n_frames, "fps": self.fps, "notes": self.notes,
                "shots": [asdict(s) for s in self.shots]}

    def write(self, path: str | Path) -> Path:
        from inference.clipio.atomic import atomic_write_text

        return atomic_write_text(Path(path), json.dumps(self.to_dict(), indent=1) + "\n")

    @classmethod
    def read(cls, path: str | Path) -> ShotReport:
        """Read ``shots.json``; :class:`~inference.clipio.FormatError` naming the file when malformed."""
        from inference.clipio import FormatError
        from inference.clipio.structured import load_json

        d = load_json(path)
        fix = "delete shots.json and re-run rally3d infer (it is rewritten)"
        try:
            shots = [Shot(int(s["start"]), int(s["stop"]), bool(s["court_view"]), float(s["score"]), str(s["how"]))
                     for s in d["shots"]]
            report = cls(shots, int(d["n_frames"]), float(d["fps"]), [str(n) for n in d.get("notes", [])])
        except (KeyError, TypeError, ValueError) as e:
            raise FormatError(path, f"not a shots file ({e!r})", fix=fix) from None
        if [s.start for s in shots[1:]] != [s.stop for s in shots[:-1]] or not shots or shots[0].start != 0 \
                or shots[-1].stop != report.n_frames:
            raise FormatError(path, "the shots do not cover the frames in order without gaps", fix=fix)
        return report


# ---------------------------------------------------------------------------------------------- cuts
def thumbnail(frame: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 → (27, 48, 3) float32 area-averaged thumbnail."""
    import cv2

    return cv2.resize(frame, THUMB, interpolation=cv2.INTER_AREA).astype(np.float32)


def cut_frames(thumbs: np.ndarray, fps: float) -> list[int]:
    """Frames that start a new shot (never 0) from (N, 27, 48, 3) thumbnails (see the module docstring)."""
    if len(thumbs) < 2:
        return []
    d = np.abs(np.diff(thumbs, axis=0)).mean(axis=(1, 2, 3))  # d[i-1]: frame i vs i-1
    half = max(3, int(round(0.25 * fps)))
    cuts = []
    for i, di in enumerate(d, start=1):
        around = np.concatenate([d[max(0, i - 1 - half):i - 1], d[i:i + half]])
        base = float(np.median(around)) if len(around) else 0.0
        if di > CUT_MIN and di > CUT_RATIO * base:
            cuts.append(i)
    return cuts


# ---------------------------------------------------------------------------------------- the shots
def find_shots(clip, camera=None, court=None, *, frames: Iterable[np.ndarray] | None = None,
               progress: bool = False) -> ShotReport:
    """Split ``clip`` (:class:`inference.clipio.Clip`) into shots and tell court views (module docstring).

    Args:
        camera, court: the calibrated camera and the court; without them shots are judged by similarity.
        frames: the clip's frames in order (default: decoded from the clip); masked regions (clip.yaml
            ``mask``) are filled before anything is measured.
    """
    from inference.masks import apply_mask, clip_mask

    rects = clip_mask(clip)
    fps = clip.info.fps
    src = None
    if frames is None:
        src = clip.frames(cache_size=0)
        frames = src.iter()
    try:
        from tqdm import tqdm

        thumbs = np.stack([thumbnail(apply_mask(f, rects)) for f in tqdm(frames, desc="shots", unit="frame",
                                                                           disable=not progress)])
    finally:
        if src is not None:
            src.close()
    n = len(thumbs)
    bounds = [0, *cut_frames(thumbs, fps), n]
    spans = list(zip(bounds[:-1], bounds[1:]))
    notes: list[str] = []
    shots: list[Shot] | None = None
    if len(spans) == 1:
        shots = [Shot(0, n, True, 1.0, "single shot")]
    elif camera is not None and court is not None:
        shots = _by_court_lines(clip, spans, camera, court, rects)
        if not any(s.court_view for s in shots):
            notes.append("the calibrated court lines were found in no shot: judged by similarity to the longest")
            shots = None
    if shots is None:
        shots = _by_similarity(thumbs, spans)
    return ShotReport(shots, n, fps, notes)


def _by_court_lines(clip, spans, camera, court, rects) -> list[Shot]:
    from inference.courtfit.drift import court_line_samples, frame_shift
    from inference.masks import apply_mask

    samples = court_line_samples(camera, court)
    support = []
    with clip.frames(cache_size=0) as src:
        for a, b in spans:
            picks = sorted({a + (b - a) * k // 4 for k in (1, 2, 3)})
            support.append(float(np.median([frame_shift(apply_mask(src.read(i), rects), samples)[1]
                                            for i in picks])))
    need = max(SUPPORT_MIN, SUPPORT_OF_BEST * max(support))
    return [Shot(a, b, s >= need, round(s, 4), "court lines") for (a, b), s in zip(spans, support)]


def _by_similarity(thumbs: np.ndarray, spans) -> list[Shot]:
    means = [thumbs[a:b].mean(axis=0) for a, b in spans]
    main = int(np.argmax([b - a for a, b in spans]))
    shots = []
    for (a, b), m in zip(spans, means):
        diff = float(np.abs(m - means[main]).mean())
        shots.append(Shot(a, b, diff <= SIMILAR_MAX, round(diff, 3), "similarity"))
    return shots


def shot_rows(table, start: int, stop: int):
    """The rows of a frame-indexed table (``BallTrack``, ``HitEvents``, ``PlayerTracks``) with
    ``start <= frame < stop``, frames renumbered from 0 (a shot as a clip of its own)."""
    import dataclasses

    keep = (table.frame >= start) & (table.frame < stop)
    values = {}
    for f in dataclasses.fields(table):
        v = getattr(table, f.name)
        if isinstance(v, dict):
            v = {k: np.asarray(x)[keep] for k, x in v.items()}
        elif isinstance(v, np.ndarray) and len(v) == len(keep):
            v = v[keep]
        values[f.name] = v
    values["frame"] = values["frame"] - start
    return type(table)(**values)


def segments(active: np.ndarray) -> list[tuple[int, int]]:
    """Runs of True in a (N,) bool array as ``[(start, stop), ...]``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], active.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist()))
