"""Scenes of a broadcast clip: where the editor cut (replays, close-ups, crowd) and which scenes show the court.

A *scene* is the stretch of video between two cuts (PySceneDetect's word); a *court-view scene* is one that
shows the court from the calibrated camera. (A player's *shot* — a racket hit to the next — is another thing:
``labeler/review/shots.py``.)

1. **Cuts.** Every frame is shrunk to a 48×27 colour thumbnail; the mean absolute difference between
   consecutive thumbnails jumps at a cut. A frame starts a new scene when its difference is above
   :data:`CUT_MIN` grey levels *and* :data:`CUT_RATIO` × the median difference of the frames around it
   (a moving camera or players raise the baseline, not the jump). Scenes shorter than :data:`MIN_SCENE_S`
   (the frames of a wipe or a dissolve) are kept as scenes of their own.
2. **Court view or not.** With a camera (``camera.yaml``), a scene shows the court when the calibrated
   court lines, shifted by up to ±24 px for drift, fall on painted-line pixels in its frames (the median
   support over three of its frames, :func:`inference.courtfit.drift.frame_shift`, at least
   :data:`SUPPORT_MIN` and at least :data:`SUPPORT_OF_BEST` × the best scene's: another court's lines
   meet a few of ours by chance, a tennis court under a padel camera scores ~0.3). Without a
   camera — or when no scene passes — the longest scene is the main view and a scene shows the court when
   its mean thumbnail is within :data:`SIMILAR_MAX` grey levels of the main view's.

A clip with one scene is a court view whatever the scores say (the user chose it). ``rally3d infer``
writes the result as ``scenes.json`` (docs/formats.md) and runs the ball detector on court-view frames only;
the other frames are reported as unseen (visibility 0). The hit-event model and the 3D fit then run on
each court-view scene on its own (:mod:`inference.pipeline.per_scene`): no event window, no flight joins
frames across a cut. Clip folders written before the file got its name hold the same table under an older
name; :func:`scenes_file` finds it and :meth:`SceneReport.read` reads it.

Example:
    >>> report = find_scenes(clip, camera, court)
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
MIN_SCENE_S = 0.2
SUPPORT_MIN = 0.3
SUPPORT_OF_BEST = 0.6
SIMILAR_MAX = 14.0
SCENES_VERSION = 1
SCENES_FILE = "scenes.json"
#: the name scenes.json had before issue 43 (a player's shot is another thing); read, never written
LEGACY_FILE = "shots.json"


@dataclass
class Scene:
    """Frames ``start .. stop-1`` between two cuts.

    Attributes:
        court_view: the scene shows the court from the calibrated (main) camera.
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
class SceneReport:
    """The scenes of a clip, in order, covering frames ``0 .. n_frames-1``."""

    scenes: list[Scene]
    n_frames: int
    fps: float
    notes: list[str] = field(default_factory=list)

    def active(self) -> np.ndarray:
        """(n_frames,) bool: frames of court-view scenes."""
        out = np.zeros(self.n_frames, bool)
        for s in self.scenes:
            out[s.start:s.stop] = s.court_view
        return out

    def court_spans(self) -> list[tuple[int, int]]:
        """``[(start, stop), ...]`` of the court-view scenes, in order; two court views either side of a cut
        stay apart (the time across a cut is not continuous)."""
        return [(s.start, s.stop) for s in self.scenes if s.court_view]

    def summary(self) -> str:
        court = [s for s in self.scenes if s.court_view]
        left = self.n_frames - sum(s.n_frames for s in court)
        text = f"{len(self.scenes)} scene{'s' if len(self.scenes) != 1 else ''}, {len(court)} court view"
        if left:
            text += (f"; {left} frames outside court views left out (frames " +
                     ", ".join(f"{s.start}–{s.stop - 1}" for s in self.scenes if not s.court_view) + ")")
        return text + "".join(f"; {n}" for n in self.notes)

    def table(self) -> str:
        lines = ["scene  frames          seconds        court view  score  by"]
        for k, s in enumerate(self.scenes):
            lines.append(f"{k:5d}  {s.start:6d}–{s.stop - 1:<6d}  {s.start / self.fps:6.2f}–{s.stop / self.fps:<6.2f}  "
                         f"{'yes' if s.court_view else 'no':<10}  {s.score:5.2f}  {s.how}")
        return "\n".join(lines + [self.summary()])

    def to_dict(self) -> dict:
        return {"version": SCENES_VERSION, "n_frames": self.n_frames, "fps": self.fps, "notes": self.notes,
                "scenes": [asdict(s) for s in self.scenes]}

    def write(self, path: str | Path) -> Path:
        from inference.clipio.atomic import atomic_write_text

        return atomic_write_text(Path(path), json.dumps(self.to_dict(), indent=1) + "\n")

    @classmethod
    def read(cls, path: str | Path) -> SceneReport:
        """Read ``scenes.json``, or a file of the older name (:func:`scenes_file`), whose list of scenes is
        called ``shots``; :class:`~inference.clipio.FormatError` naming the file when malformed."""
        from inference.clipio import FormatError
        from inference.clipio.structured import load_json

        d = load_json(path)
        fix = f"delete {Path(path).name} and re-run rally3d infer (scenes.json is rewritten)"
        try:
            rows = d["shots"] if "shots" in d and "scenes" not in d else d["scenes"]  # "shots": the old file
            scenes = [Scene(int(s["start"]), int(s["stop"]), bool(s["court_view"]), float(s["score"]), str(s["how"]))
                      for s in rows]
            report = cls(scenes, int(d["n_frames"]), float(d["fps"]), [str(n) for n in d.get("notes", [])])
        except (KeyError, TypeError, ValueError) as e:
            raise FormatError(path, f"not a scenes file ({e!r})", fix=fix) from None
        if [s.start for s in scenes[1:]] != [s.stop for s in scenes[:-1]] or not scenes or scenes[0].start != 0 \
                or scenes[-1].stop != report.n_frames:
            raise FormatError(path, "the scenes do not cover the frames in order without gaps", fix=fix)
        return report


def scenes_file(root: str | Path) -> Path:
    """The file a clip folder's scenes are read from: ``scenes.json``; in a folder written before that name
    (issue 43), with only the old :data:`LEGACY_FILE`, that one (:meth:`SceneReport.read` reads both). The
    path of ``scenes.json`` when there is neither."""
    new, old = Path(root) / SCENES_FILE, Path(root) / LEGACY_FILE
    return old if old.is_file() and not new.is_file() else new


# ---------------------------------------------------------------------------------------------- cuts
def thumbnail(frame: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 → (27, 48, 3) float32 area-averaged thumbnail."""
    import cv2

    return cv2.resize(frame, THUMB, interpolation=cv2.INTER_AREA).astype(np.float32)


def cut_frames(thumbs: np.ndarray, fps: float) -> list[int]:
    """Frames that start a new scene (never 0) from (N, 27, 48, 3) thumbnails (see the module docstring)."""
    if len(thumbs) < 2:
        return []
    return cuts_from_diffs(np.abs(np.diff(thumbs, axis=0)).mean(axis=(1, 2, 3)), fps)


def cuts_from_diffs(d: np.ndarray, fps: float) -> list[int]:
    """Frames that start a new scene from ``d (N-1,)``, the mean absolute difference of each frame's thumbnail
    to the previous one's (``d[i-1]``: frame ``i`` vs ``i-1``; a streamed video keeps only these)."""
    half = max(3, int(round(0.25 * fps)))
    cuts = []
    for i, di in enumerate(d, start=1):
        around = np.concatenate([d[max(0, i - 1 - half):i - 1], d[i:i + half]])
        base = float(np.median(around)) if len(around) else 0.0
        if di > CUT_MIN and di > CUT_RATIO * base:
            cuts.append(i)
    return cuts


# --------------------------------------------------------------------------------------- the scenes
def find_scenes(clip, camera=None, court=None, *, frames: Iterable[np.ndarray] | None = None,
                progress: bool = False) -> SceneReport:
    """Split ``clip`` (:class:`inference.clipio.Clip`) into scenes and tell court views (module docstring).

    Args:
        camera, court: the calibrated camera and the court; without them scenes are judged by similarity.
        frames: the clip's frames in order (default: decoded from the clip); masked regions (clip.yaml
            ``mask``) are filled before anything is measured.
    """
    from inference.video.masks import apply_mask, clip_mask

    rects = clip_mask(clip)
    fps = clip.info.fps
    src = None
    if frames is None:
        src = clip.frames(cache_size=0)
        frames = src.iter()
    try:
        from tqdm import tqdm

        thumbs = np.stack([thumbnail(apply_mask(f, rects)) for f in tqdm(frames, desc="scenes", unit="frame",
                                                                            disable=not progress)])
    finally:
        if src is not None:
            src.close()
    n = len(thumbs)
    bounds = [0, *cut_frames(thumbs, fps), n]
    spans = list(zip(bounds[:-1], bounds[1:]))
    notes: list[str] = []
    scenes: list[Scene] | None = None
    if len(spans) == 1:
        scenes = [Scene(0, n, True, 1.0, "single scene")]
    elif camera is not None and court is not None:
        scenes = _by_court_lines(clip, spans, camera, court, rects)
        if not any(s.court_view for s in scenes):
            notes.append("the calibrated court lines were found in no scene: judged by similarity to the longest")
            scenes = None
    if scenes is None:
        scenes = _by_similarity(thumbs, spans)
    return SceneReport(scenes, n, fps, notes)


def _by_court_lines(clip, spans, camera, court, rects) -> list[Scene]:
    from inference.courtfit.drift import court_line_samples, frame_shift
    from inference.video.masks import apply_mask

    samples = court_line_samples(camera, court)
    support = []
    with clip.frames(cache_size=0) as src:
        for a, b in spans:
            picks = sorted({a + (b - a) * k // 4 for k in (1, 2, 3)})
            support.append(float(np.median([frame_shift(apply_mask(src.read(i), rects), samples)[1]
                                            for i in picks])))
    need = max(SUPPORT_MIN, SUPPORT_OF_BEST * max(support))
    return [Scene(a, b, s >= need, round(s, 4), "court lines") for (a, b), s in zip(spans, support)]


def _by_similarity(thumbs: np.ndarray, spans) -> list[Scene]:
    means = [thumbs[a:b].mean(axis=0) for a, b in spans]
    main = int(np.argmax([b - a for a, b in spans]))
    scenes = []
    for (a, b), m in zip(spans, means):
        diff = float(np.abs(m - means[main]).mean())
        scenes.append(Scene(a, b, diff <= SIMILAR_MAX, round(diff, 3), "similarity"))
    return scenes


def scene_rows(table, start: int, stop: int):
    """The rows of a frame-indexed table (``BallTrack``, ``HitEvents``, ``PlayerTracks``) with
    ``start <= frame < stop``, frames renumbered from 0 (a scene as a clip of its own)."""
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
