"""Importers of pose predictions made by outside tools: the always-available pose path.

:func:`load_predictions` reads MMPose/RTMPose JSON, COCO keypoint JSON, OpenPose JSON, Ultralytics
``Results.summary()`` JSON or a flat CSV and returns a :class:`PoseSequence` in COCO-17 order, in pixels
of the original frame (layouts: ``docs/formats.md``, "Outside formats"). Every format goes through one
converter (:func:`_person`) and one validation helper (:func:`_numbers`), so every problem is a
:class:`FormatError` naming the file, the entry (frame and instance, or the CSV line) and the fix.

Conventions shared by all formats:

* A keypoint is **missing** (NaN position, score 0) when its score is 0 (COCO ``v = 0``, OpenPose
  ``c = 0``) or when its coordinates are wildly outside the image: beyond ±10× the image size
  (``image_size`` given) or beyond ±100 000 px (size unknown). Keypoints merely outside the frame are
  kept: they are real predictions near the border.
* Keypoint scores are clipped to [0, 1]. A person's score is its box score, else the mean of its
  keypoint scores. A person with neither a box nor any keypoint is dropped.
* Frame numbers written in a file (``frame_id``, ``image_id``, the number in a per-frame file name, the
  ``frame`` column of a pixel CSV) become ``frame = number - frame_offset``. The default offset is the
  one the tool counts from: 1 for ``topdown_demo_with_mmdet.py`` videos, 0 otherwise. Frames given by
  position (a list over frames, the order of COCO ``images``) and players.csv frames are indices already.
* The sequence holds one :class:`Persons` per frame from 0 to the last frame seen (or ``n_frames``),
  ``Persons.empty()`` where a frame had no entry.
"""
from __future__ import annotations

import json
import re
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from inference.clipio.atomic import atomic_write_text
from inference.clipio.csvtable import CsvTable, duplicated, read_text
from inference.clipio.errors import FormatError
from inference.clipio.players import KP_COLUMNS, read_players_csv

from .types import J, Persons, PoseSequence

FORMATS = ("auto", "mmpose", "coco", "openpose", "csv", "ultralytics")
"""Values of ``fmt`` accepted by :func:`load_predictions`."""

KEYPOINT_LAYOUTS = {17: "COCO-17", 26: "Halpe26", 133: "COCO-WholeBody"}
"""Keypoint counts whose first 17 keypoints are COCO-17 (MMPose, COCO, Ultralytics)."""

OPENPOSE_TO_COCO17 = {
    25: (0, 16, 15, 18, 17, 5, 2, 6, 3, 7, 4, 12, 9, 13, 10, 14, 11),  # BODY_25
    18: (0, 15, 14, 17, 16, 5, 2, 6, 3, 7, 4, 11, 8, 12, 9, 13, 10),  # COCO-18
}
"""OpenPose keypoint index of each COCO-17 joint, by the model's keypoint count."""

FAR_FACTOR = 10.0
"""A keypoint beyond ±``FAR_FACTOR`` × the image size is treated as missing."""
FAR_PX = 1e5
"""The same limit in pixels when the image size is unknown."""

PIXEL_CSV_COLUMNS = ("frame", "person", *KP_COLUMNS)
BOX_COLUMNS = ("x1", "y1", "x2", "y2")

EXPECTED_LAYOUTS = (
    'MMPose/RTMPose [{"frame_id": 0, "instances": [...]}, ...], {"meta_info": ..., "instance_info": [...]} '
    'or [{"keypoints": [[x, y], ...], "keypoint_scores": [...]}, ...]; '
    'COCO [{"image_id", "keypoints": [x, y, v, ...]}] or {"images": [...], "annotations": [...]}; '
    'OpenPose {"people": [{"pose_keypoints_2d": [...]}]}; '
    'Ultralytics [{"box": {...}, "keypoints": {"x": [...], "y": [...]}}]; CSV (*.csv)'
)


# ------------------------------------------------------------------------------------ public API
def load_predictions(
    path: str | Path,
    *,
    n_frames: int | None = None,
    fmt: str = "auto",
    frame_offset: int | None = None,
    image_size: tuple[float, float] | None = None,
) -> PoseSequence:
    """Read pose predictions of an outside tool (a file or a folder of per-frame files).

    Args:
        path: the file, or a folder of per-frame JSON files named by frame number (MMPose instance
            lists, OpenPose ``*_keypoints.json``, Ultralytics ``summary()`` lists).
        n_frames: frames of the video; frames at or past it are an error, and the sequence has exactly
            this many frames.
        fmt: one of :data:`FORMATS`; ``"auto"`` tells the format from the extension and the content.
        frame_offset: the frame number that means frame 0 (overrides the detected base).
        image_size: ``(width, height)`` in pixels: needed for players.csv (normalised coordinates) and
            sets the "wildly outside" limit.

    Returns:
        ``PoseSequence`` with ``frames[i]`` = the people of frame ``i``: boxes (N, 4), keypoints
        (N, 17, 2) px, kp_scores (N, 17), scores (N,), track_ids (N,).

    Raises:
        FormatError: the file is missing or malformed (names the file, the entry or line, and the fix).
        ValueError: a bad argument.
    """
    path = Path(path)
    opts = _Options.checked(n_frames, frame_offset, image_size)
    if fmt not in FORMATS:
        raise ValueError(f"fmt must be one of {', '.join(FORMATS)}, got {fmt!r}")
    if path.is_dir():
        fmt = _detect_folder(path) if fmt == "auto" else fmt
        if fmt not in _FRAME_READERS:
            raise FormatError(path, f"is a folder, but {fmt} predictions are one file",
                              fix=f"pass the {fmt} file itself, not its folder")
        frames = _load_folder(path, fmt, opts)
    elif fmt == "csv" or (fmt == "auto" and path.suffix.lower() == ".csv"):
        fmt = "csv"
        frames = _load_csv(path, opts)
    else:
        data = _read_json(path)
        fmt = _detect_json(path, data) if fmt == "auto" else fmt
        frames = _FILE_LOADERS[fmt](_Where(path), data, opts)
    return frames.sequence(f"{fmt}:{path}")


def write_mmpose_json(path: str | Path, seq: PoseSequence, frame_base: int = 0) -> Path:
    """Write ``seq`` in the ``MMPoseInferencer`` video layout, atomically.

    Layout: ``[{"frame_id": i + frame_base, "instances": [{"keypoints": [[x, y]] * 17,
    "keypoint_scores": [17], "bbox": [[x1, y1, x2, y2]], "bbox_score": s, "track_id": t}]}]``.
    Missing keypoints (NaN) are written as ``[0, 0]`` with score 0, which :func:`load_predictions` reads
    back as missing; ``bbox``/``bbox_score``/``track_id`` are left out when unknown (NaN or -1).
    Read it back with ``load_predictions(path, frame_offset=frame_base)``.
    """
    entries = [
        {"frame_id": i + frame_base, "instances": [_mmpose_record(persons, n) for n in range(len(persons))]}
        for i, persons in enumerate(seq.frames)
    ]
    return atomic_write_text(path, json.dumps(entries, allow_nan=False))


def _mmpose_record(persons: Persons, n: int) -> dict:
    """Person ``n`` of ``persons`` as an MMPose instance dict."""
    kp, s = persons.keypoints[n], persons.kp_scores[n]
    missing = np.isnan(kp).any(axis=1) | ~(s > 0)
    record: dict = {
        "keypoints": np.where(missing[:, None], 0.0, kp).tolist(),
        "keypoint_scores": np.where(missing, 0.0, s).tolist(),
    }
    if np.isfinite(persons.boxes[n]).all():
        record["bbox"] = [persons.boxes[n].tolist()]
    if np.isfinite(persons.scores[n]):
        record["bbox_score"] = float(persons.scores[n])
    if persons.track_ids[n] >= 0:
        record["track_id"] = int(persons.track_ids[n])
    return record


# -------------------------------------------------------------------------------- shared helpers
@dataclass(frozen=True)
class _Options:
    """The caller's arguments, checked."""

    n_frames: int | None
    frame_offset: int | None
    image_size: tuple[float, float] | None

    @classmethod
    def checked(cls, n_frames, frame_offset, image_size) -> _Options:
        if n_frames is not None and (isinstance(n_frames, bool) or int(n_frames) != n_frames or n_frames < 0):
            raise ValueError(f"n_frames must be a whole number >= 0, got {n_frames!r}")
        if frame_offset is not None and (isinstance(frame_offset, bool) or int(frame_offset) != frame_offset):
            raise ValueError(f"frame_offset must be a whole number, got {frame_offset!r}")
        if image_size is not None:
            size = np.asarray(image_size, dtype=float)
            if size.shape != (2,) or not (np.isfinite(size).all() and (size > 0).all()):
                raise ValueError(f"image_size must be (width, height) > 0, got {image_size!r}")
            image_size = (float(size[0]), float(size[1]))
        return cls(None if n_frames is None else int(n_frames),
                   None if frame_offset is None else int(frame_offset), image_size)

    @property
    def far(self) -> np.ndarray:
        """(2,) |x|, |y| limits in pixels beyond which a keypoint is treated as missing."""
        if self.image_size is None:
            return np.array([FAR_PX, FAR_PX])
        return FAR_FACTOR * np.asarray(self.image_size)


@dataclass(frozen=True)
class _Where:
    """Where a value sits, for error messages: the file, the entry inside it and the CSV line."""

    path: Path
    entry: str = ""
    line: int | None = None

    def at(self, entry: str) -> _Where:
        """A place inside this one (``"frame 3"`` → ``"frame 3, instance 1"``)."""
        return _Where(self.path, f"{self.entry}, {entry}" if self.entry else entry, self.line)

    def error(self, problem: str, fix: str = "") -> FormatError:
        return FormatError(self.path, f"{self.entry}: {problem}" if self.entry else problem,
                           line=self.line, fix=fix)


@dataclass
class _Person:
    """One person, converted: keypoints (17, 2) px, kp_scores (17,), box (4,) xyxy px (NaN unknown)."""

    keypoints: np.ndarray
    kp_scores: np.ndarray
    box: np.ndarray
    score: float
    track_id: int = -1

    @property
    def is_empty(self) -> bool:
        """Neither a box nor any keypoint: nothing to locate."""
        return bool(np.isnan(self.box).any() and np.isnan(self.keypoints).all())


def _brief(value) -> str:
    """A short text of a JSON value for messages."""
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _numbers(value, shape: tuple[int | None, ...], where: _Where, what: str, fix: str,
             *, allow_nan: bool = False) -> np.ndarray:
    """The one validation helper: ``value`` as a float array of ``shape`` (None = any length).

    ``FormatError`` for anything that is not numbers of that shape (strings, null, booleans, ragged
    lists) and for NaN/inf (NaN is allowed with ``allow_nan``: empty CSV cells).
    """
    try:
        arr = np.asarray(value)
    except ValueError:  # a ragged list
        arr = np.asarray(None)
    fits = arr.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, arr.shape))
    if arr.dtype.kind not in "iuf" or not fits:
        dims = ", ".join("K" if s is None else str(s) for s in shape)
        dims = f"shape ({dims})" if shape else "a number"
        raise where.error(f"{what} must be numbers of {dims}, got {_brief(value)}", fix)
    arr = arr.astype(np.float64)
    bad = np.isinf(arr) if allow_nan else ~np.isfinite(arr)
    if bad.any():
        at = tuple(int(i) for i in np.argwhere(bad)[0])
        place = f" at index {at[0] if len(at) == 1 else list(at)}" if at else ""
        raise where.error(f"{what} holds NaN or infinite values{place}", fix)
    return arr


def _integer(value, where: _Where, what: str, fix: str = "") -> int:
    """``value`` as an int; ``FormatError`` unless it is a whole number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not float(value).is_integer():
        raise where.error(f"{what} must be a whole number, got {_brief(value)}", fix)
    return int(value)


def _field(obj, key: str, where: _Where, what: str, fix: str):
    """``obj[key]``; ``FormatError`` when ``obj`` is not a JSON object or has no ``key``."""
    if not isinstance(obj, dict):
        raise where.error(f"{what} must be a JSON object, got {_brief(obj)}", fix)
    if key not in obj:
        raise where.error(f"{what} has no {key!r} (keys: {', '.join(map(str, obj)) or 'none'})", fix)
    return obj[key]


def _list(value, where: _Where, what: str, fix: str) -> list:
    """``value``; ``FormatError`` unless it is a JSON list."""
    if not isinstance(value, list):
        raise where.error(f"{what} must be a JSON list, got {_brief(value)}", fix)
    return value


def _unwrap(value):
    """``[v]`` → ``v`` (MMPose nests ``bbox`` and sometimes ``bbox_score`` one level)."""
    return value[0] if isinstance(value, list) and len(value) == 1 else value


def _person(
    where: _Where,
    opts: _Options,
    xy,
    scores=None,
    *,
    box=None,
    score=None,
    track_id=-1,
    joints: tuple[int, ...] | None = None,
    xywh: bool = False,
    empty_is_missing: bool = False,
) -> _Person:
    """The one converter: raw values of any format → a validated COCO-17 :class:`_Person`.

    Args:
        where: the instance, for messages.
        xy: (K, 2) keypoint pixels (JSON lists or an array).
        scores: (K,) keypoint confidences, or None (all 1).
        box: (4,) ``x1, y1, x2, y2`` (``x, y, w, h`` with ``xywh``), possibly nested ``[[...]]``; None.
        score: person confidence, or None (the mean keypoint score).
        track_id: identity from the file, -1 when none.
        joints: the index in K of each COCO-17 joint; None = the first 17 and K must be 17, 26 or 133.
        empty_is_missing: NaN (an empty CSV cell) means "unknown" instead of an error.
    """
    kp_fix = "write keypoints as pixel [x, y] pairs, one per keypoint"
    xy = _numbers(xy, (None, 2), where, "keypoints", kp_fix, allow_nan=empty_is_missing)
    k = len(xy)
    if joints is None:
        if k not in KEYPOINT_LAYOUTS:
            known = ", ".join(f"{n} ({name})" for n, name in KEYPOINT_LAYOUTS.items())
            raise where.error(f"{k} keypoints; expected {known}", fix="export a model whose first 17 "
                              "keypoints are COCO-17 (a COCO, Halpe26 or wholebody model)")
        joints = tuple(range(J))
    s = np.ones(k)
    if scores is not None:
        s = _numbers(scores, (k,), where, "keypoint scores", f"write {k} numbers, one score per keypoint",
                     allow_nan=empty_is_missing)
    xy, s = xy[list(joints)], np.clip(np.nan_to_num(s[list(joints)], nan=1.0), 0.0, 1.0)
    missing = np.isnan(xy).any(axis=1) | (s <= 0) | (np.abs(xy) > opts.far).any(axis=1)
    xy[missing], s[missing] = np.nan, 0.0
    box = _box(where, box, xywh, empty_is_missing)
    if score is None or (empty_is_missing and np.isnan(score)):
        score = float(s[~missing].mean()) if (~missing).any() else 0.0
    else:
        score = float(_numbers(_unwrap(score), (), where, "person score", "write the score as a number"))
    track_id = _integer(track_id, where, "track id", "write the track id as a whole number (or leave it out)")
    return _Person(xy, s, box, score, track_id)


def _box(where: _Where, box, xywh: bool, empty_is_missing: bool) -> np.ndarray:
    """(4,) ``x1, y1, x2, y2`` pixels from a raw box (NaN when absent); see :func:`_person`."""
    if box is None:
        return np.full(4, np.nan)
    names = "x, y, w, h" if xywh else "x1, y1, x2, y2"
    fix = f"write the box as [{names}] in pixels"
    box = _numbers(_unwrap(box), (4,), where, "bbox", fix, allow_nan=empty_is_missing)
    if np.isnan(box).any():
        return np.full(4, np.nan)
    if xywh:
        if (box[2:] < 0).any():
            raise where.error(f"bbox {box.tolist()} has a negative width or height", fix)
        box[2:] += box[:2]
    elif (box[2:] < box[:2]).any():
        raise where.error(f"bbox {box.tolist()} has x2 < x1 or y2 < y1", fix)
    return box


class _Frames:
    """People per frame index, checked as they are added; :meth:`sequence` makes the result."""

    def __init__(self, path: Path, opts: _Options, base: int = 0):
        self.path = path
        self.opts = opts
        self.base = base if opts.frame_offset is None else opts.frame_offset
        self.people: dict[int, list[_Person]] = {}
        self._origin: dict[int, str] = {}

    def index(self, where: _Where, number) -> int:
        """The frame index of a frame number written in the file (``number - base``, checked >= 0)."""
        number = _integer(number, where, "frame number", "write frame numbers as whole numbers")
        frame = number - self.base
        if frame < 0:
            raise where.error(f"frame number {number} gives frame {frame} < 0 "
                              f"(frame numbers count from {self.base})",
                              fix="frame numbers must be >= the first frame's; pass frame_offset= to set it")
        return frame

    def put(self, where: _Where, frame: int, people: list[_Person], *, unique: bool = True) -> int:
        """Add ``people`` to frame ``frame``; with ``unique``, a second entry for a frame is an error."""
        n = self.opts.n_frames
        if n is not None and frame >= n:
            raise where.error(f"frame {frame} is beyond the video ({n} frames)",
                              fix=f"frames must be in 0..{n - 1}; check n_frames and frame_offset")
        if unique and frame in self._origin:
            raise where.error(f"duplicate entry for frame {frame} (first in {self._origin[frame]})",
                              fix="keep one entry per frame")
        here = where.entry if where.path == self.path else where.path.name
        self._origin.setdefault(frame, here or where.path.name)
        self.people.setdefault(frame, []).extend(p for p in people if not p.is_empty)
        return frame

    def sequence(self, source: str) -> PoseSequence:
        """One :class:`Persons` per frame from 0 to the last frame (or ``n_frames``)."""
        n = self.opts.n_frames if self.opts.n_frames is not None else max(self.people, default=-1) + 1
        return PoseSequence([_stack(self.people.get(f, [])) for f in range(n)], source)


def _stack(people: list[_Person]) -> Persons:
    """The people of one frame as :class:`Persons`."""
    if not people:
        return Persons.empty()
    return Persons(
        np.stack([p.box for p in people]),
        np.stack([p.keypoints for p in people]),
        np.stack([p.kp_scores for p in people]),
        np.array([p.score for p in people]),
        np.array([p.track_id for p in people]),
    )


def _read_json(path: Path):
    """The parsed JSON of ``path``; ``FormatError`` when missing or not JSON."""
    text = read_text(path)
    try:
        return json.loads(text)
    except json.JSONDecodeError as err:
        raise FormatError(path, f"not JSON ({err.msg}, column {err.colno})", line=err.lineno,
                          fix="pass the predictions JSON the tool wrote (or fmt='csv' for a CSV)") from None


# ------------------------------------------------------------------------------- format detection
def _sniff(data) -> str | None:
    """The format of a parsed JSON document, or None when it cannot tell (or it is an empty list)."""
    if isinstance(data, dict):
        if "instance_info" in data:
            return "mmpose"
        if "annotations" in data or "images" in data:
            return "coco"
        return "openpose" if "people" in data else None
    if not isinstance(data, list) or not data:
        return None
    first = data[0]
    if isinstance(first, list):
        return "ultralytics"
    if not isinstance(first, dict):
        return None
    if "frame_id" in first or "keypoint_scores" in first:
        return "mmpose"
    if "image_id" in first:
        return "coco"
    if "box" in first or isinstance(first.get("keypoints"), dict):
        return "ultralytics"
    return "mmpose" if isinstance(first.get("keypoints"), list) else None


def _detect_json(path: Path, data) -> str:
    """The format of one JSON file; ``FormatError`` saying what was expected when it cannot tell."""
    if data == []:
        return "mmpose"  # an image with nobody
    fmt = _sniff(data)
    if fmt is None:
        raise FormatError(path, f"cannot tell the pose format of {_brief(data)}; expected {EXPECTED_LAYOUTS}",
                          fix=f"pass fmt= one of {', '.join(FORMATS[1:])}")
    return fmt


def _detect_folder(folder: Path) -> str:
    """The format of a folder of per-frame JSON files (OpenPose, MMPose or Ultralytics)."""
    files = _json_files(folder)
    if any(f.name.endswith("_keypoints.json") for f in files):
        return "openpose"
    for file in files:
        fmt = _sniff(_read_json(file))
        if fmt in _FRAME_READERS:
            return fmt
        if fmt is not None:
            raise FormatError(file, f"holds {fmt} predictions for a whole clip, not one frame",
                              fix="pass this file instead of the folder")
    return "mmpose"  # every frame empty: any per-frame reader gives the same


# ---------------------------------------------------------------------------------------- MMPose
def _mmpose_frame(data, where: _Where, opts: _Options) -> list[_Person]:
    """One frame of MMPose/RTMPose: ``[instance, ...]``."""
    items = _list(data, where, "the instances", 'write the instances as a list [{"keypoints": ...}, ...]')
    return [_mmpose_instance(inst, where.at(f"instance {i}"), opts) for i, inst in enumerate(items)]


def _mmpose_instance(inst, where: _Where, opts: _Options) -> _Person:
    """``{"keypoints": [[x, y]] * K, "keypoint_scores": [K], "bbox"?, "bbox_score"?, "track_id"?}``."""
    fix = 'each instance needs "keypoints": [[x, y], ...] and "keypoint_scores": [...]'
    xy = _field(inst, "keypoints", where, "the instance", fix)
    return _person(where, opts, xy, inst.get("keypoint_scores"), box=inst.get("bbox"),
                   score=inst.get("bbox_score"), track_id=inst.get("track_id", -1))


def _load_mmpose(where: _Where, data, opts: _Options) -> _Frames:
    """An MMPose file: inferencer video, ``topdown_demo_with_mmdet`` ``{"instance_info"}`` or an image."""
    if isinstance(data, dict):
        info = _field(data, "instance_info", where, "the predictions",
                      fix='topdown_demo_with_mmdet writes {"meta_info": ..., "instance_info": [...]}')
        return _mmpose_document(where.at("instance_info"), info, opts, video_base=1)
    return _mmpose_document(where, data, opts, video_base=0)


def _mmpose_document(where: _Where, data, opts: _Options, video_base: int) -> _Frames:
    """A list of ``{"frame_id", "instances"}`` (video, ids from ``video_base``) or of instances (image)."""
    items = _list(data, where, "the predictions", f"expected {EXPECTED_LAYOUTS}")
    frames = _Frames(where.path, opts, base=video_base)
    if not any(isinstance(e, dict) and "frame_id" in e for e in items):
        frames.put(where, 0, _mmpose_frame(items, where, opts))
        return frames
    fix = 'write each frame as {"frame_id": <int>, "instances": [...]}'
    for i, entry in enumerate(items):
        number = _field(entry, "frame_id", where.at(f"entry {i}"), "the frame entry", fix)
        w = where.at(f"entry {i} (frame_id {_brief(number)})")
        instances = _field(entry, "instances", w, "the frame entry", fix)
        frames.put(w, frames.index(w, number), _mmpose_frame(instances, w, opts))
    return frames


# ------------------------------------------------------------------------------------------ COCO
def _coco_person(ann, where: _Where, opts: _Options, default_score: float | None) -> _Person:
    """A COCO annotation/result: ``keypoints`` flat ``[x, y, v] * K``, ``bbox`` ``[x, y, w, h]``."""
    fix = "write keypoints flat as [x1, y1, v1, x2, y2, v2, ...] in pixels"
    flat = _numbers(_field(ann, "keypoints", where, "the annotation", fix), (None,), where, "keypoints", fix)
    if len(flat) % 3:
        raise where.error(f"keypoints hold {len(flat)} numbers, not x, y, v triples", fix)
    xyv = flat.reshape(-1, 3)
    return _person(where, opts, xyv[:, :2], xyv[:, 2], box=ann.get("bbox"),
                   score=ann.get("score", default_score), xywh=True)


def _is_person(ann) -> bool:
    """A person annotation (category 1, not a crowd); other categories are skipped."""
    return not isinstance(ann, dict) or (ann.get("category_id", 1) == 1 and not ann.get("iscrowd", 0))


def _load_coco(where: _Where, data, opts: _Options) -> _Frames:
    """COCO results (a list) or ground truth (``{"images", "annotations"}``)."""
    if isinstance(data, dict):
        return _coco_ground_truth(where, data, opts)
    items = _list(data, where, "COCO results", 'write [{"image_id": ..., "keypoints": [...], "score": ...}]')
    frames = _Frames(where.path, opts)
    for i, ann in enumerate(items):
        number = _field(ann, "image_id", where.at(f"entry {i}"), "the result",
                        fix="each result needs the image_id of its frame")
        w = where.at(f"entry {i} (image_id {_brief(number)})")
        if _is_person(ann):
            frames.put(w, frames.index(w, number), [_coco_person(ann, w, opts, None)], unique=False)
    return frames


def _coco_ground_truth(where: _Where, data, opts: _Options) -> _Frames:
    """COCO ground truth: frames from ``images[].file_name`` digits, else from the order of ``images``."""
    fix = 'COCO ground truth is {"images": [{"id", "file_name"}], "annotations": [...]}'
    images = _list(_field(data, "images", where, "the COCO file", fix), where.at("images"), "images", fix)
    anns = _list(_field(data, "annotations", where, "the COCO file", fix), where.at("annotations"),
                 "annotations", fix)
    ids = [_field(img, "id", where.at(f"images[{i}]"), "the image", fix) for i, img in enumerate(images)]
    numbers = [_name_number(img.get("file_name")) for img in images]
    by_name = all(n is not None for n in numbers)
    frames = _Frames(where.path, opts)
    frame_of: dict = {}
    for i, image_id in enumerate(ids):
        w = where.at(f"images[{i}] (id {_brief(image_id)})")
        if not isinstance(image_id, (int, str)) or isinstance(image_id, bool):
            raise w.error(f"image id {_brief(image_id)} is not a whole number or text", fix=fix)
        if image_id in frame_of:
            raise w.error(f"duplicate image id {_brief(image_id)}", fix="give every image a distinct id")
        frame_of[image_id] = frames.put(w, frames.index(w, numbers[i]) if by_name else i, [])
    for i, ann in enumerate(anns):
        w = where.at(f"annotations[{i}]")
        if not _is_person(ann):
            continue
        image_id = _field(ann, "image_id", w, "the annotation", fix)
        if not isinstance(image_id, (int, str)) or image_id not in frame_of:
            raise w.error(f"image_id {_brief(image_id)} is not in images",
                          fix="add the image to images or remove the annotation")
        frames.put(w, frame_of[image_id], [_coco_person(ann, w, opts, 1.0)], unique=False)
    return frames


# -------------------------------------------------------------------------------------- OpenPose
def _openpose_frame(data, where: _Where, opts: _Options) -> list[_Person]:
    """One OpenPose frame: ``{"people": [{"pose_keypoints_2d": [x, y, c] * 25}]}`` (BODY_25 or COCO-18)."""
    fix = 'OpenPose --write_json gives {"people": [{"pose_keypoints_2d": [...]}]}'
    people = _list(_field(data, "people", where, "the OpenPose frame", fix), where, "people", fix)
    return [_openpose_person(p, where.at(f"person {i}"), opts) for i, p in enumerate(people)]


def _openpose_person(person, where: _Where, opts: _Options) -> _Person:
    fix = "run OpenPose with --model_pose BODY_25 (or COCO): 25 (or 18) × x, y, c"
    flat = _numbers(_field(person, "pose_keypoints_2d", where, "the person", fix), (None,), where,
                    "pose_keypoints_2d", fix)
    k, rest = divmod(len(flat), 3)
    if rest or k not in OPENPOSE_TO_COCO17:
        raise where.error(f"pose_keypoints_2d holds {len(flat)} numbers; expected 75 (BODY_25) "
                          "or 54 (COCO-18)", fix)
    xyc = flat.reshape(k, 3)
    return _person(where, opts, xyc[:, :2], xyc[:, 2], joints=OPENPOSE_TO_COCO17[k])


# ----------------------------------------------------------------------------------- Ultralytics
def _ultralytics_frame(data, where: _Where, opts: _Options) -> list[_Person]:
    """One frame of Ultralytics ``Results.summary()``: a list of detections."""
    items = _list(data, where, "the detections", "write Results.summary() of the frame: a list of detections")
    return [_ultralytics_person(d, where.at(f"detection {i}"), opts) for i, d in enumerate(items)]


def _ultralytics_person(det, where: _Where, opts: _Options) -> _Person:
    """``{"confidence", "box": {x1, y1, x2, y2}, "keypoints": {"x": [K], "y": [K], "visible": [K]}}``."""
    fix = 'use a pose model: each detection needs "keypoints": {"x": [...], "y": [...], "visible": [...]}'
    kp = _field(det, "keypoints", where, "the detection", fix)
    x = _numbers(_field(kp, "x", where, "keypoints", fix), (None,), where, "keypoints x", fix)
    y = _numbers(_field(kp, "y", where, "keypoints", fix), (len(x),), where, "keypoints y", fix)
    box = det.get("box")
    if box is not None:
        box = [_field(box, c, where, "box", 'write "box": {"x1", "y1", "x2", "y2"}') for c in BOX_COLUMNS]
    return _person(where, opts, np.stack([x, y], axis=1), kp.get("visible"), box=box,
                   score=det.get("confidence"), track_id=det.get("track_id", -1))


def _load_ultralytics(where: _Where, data, opts: _Options) -> _Frames:
    """A list of detections (one frame) or a list over frames of such lists (frame = position)."""
    items = _list(data, where, "the predictions", "write Results.summary() per frame: [[...], [...], ...]")
    frames = _Frames(where.path, opts)
    if not any(isinstance(e, list) for e in items):
        frames.put(where, 0, _ultralytics_frame(items, where, opts))
        return frames
    for i, frame_items in enumerate(items):
        w = where.at(f"frame {i}")
        frames.put(w, i, _ultralytics_frame(frame_items, w, opts))
    return frames


# ------------------------------------------------------------------------------- per-frame folder
def _single_frame(reader: Callable[[object, _Where, _Options], list[_Person]]):
    """A file loader for one frame (frame 0) from a per-frame reader."""

    def load(where: _Where, data, opts: _Options) -> _Frames:
        frames = _Frames(where.path, opts)
        frames.put(where, 0, reader(data, where, opts))
        return frames

    return load


def _name_number(name) -> int | None:
    """The last run of digits in a file name's stem (``clip_000000000012_keypoints.json`` → 12)."""
    if not isinstance(name, str):
        return None
    digits = re.findall(r"\d+", Path(name).stem)
    return int(digits[-1]) if digits else None


def _json_files(folder: Path) -> list[Path]:
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".json" and p.is_file())
    if not files:
        raise FormatError(folder, "no .json files in the folder",
                          fix="pass a folder of per-frame JSON files named by frame number, e.g. 000012.json")
    return files


def _load_folder(folder: Path, fmt: str, opts: _Options) -> _Frames:
    """A folder of per-frame JSON files; the frame number is the last number in each file name."""
    files = _json_files(folder)
    if fmt == "openpose":
        files = [f for f in files if f.name.endswith("_keypoints.json")] or files
    read = _FRAME_READERS[fmt]
    frames = _Frames(folder, opts)
    for file in files:
        where = _Where(file)
        number = _name_number(file.name)
        if number is None:
            raise where.error("no frame number in the file name",
                              fix="name per-frame files by frame number, e.g. 000012.json")
        frame = frames.index(where, number)
        frames.put(where, frame, read(_read_json(file), where, opts))
    return frames


# ------------------------------------------------------------------------------------------- CSV
def _load_csv(path: Path, opts: _Options) -> _Frames:
    """players.csv (has ``player_id``; normalised) or the pixel CSV ``frame,person,<joint>_x,_y,_s``."""
    table = CsvTable.read(path, ("frame",), optional=PIXEL_CSV_COLUMNS[1:], ignore_case=True)
    return _players_csv(path, opts) if table.has("player_id") else _pixel_csv(path, opts)


def _players_csv(path: Path, opts: _Options) -> _Frames:
    """Our players.csv (:mod:`inference.clipio.players`): ``player_id`` becomes the track id."""
    if opts.image_size is None:
        raise FormatError(path, "players.csv coordinates are normalised, so the image size is needed",
                          fix="pass image_size=(width, height) of the video")
    tracks = read_players_csv(path, n_frames=opts.n_frames)
    scale = np.asarray(opts.image_size)
    frames = _Frames(path, opts)
    for r in range(len(tracks)):
        frame, pid = int(tracks.frame[r]), int(tracks.player_id[r])
        kp = tracks.keypoints[r]
        person = _person(_Where(path, f"frame {frame}, player_id {pid}"), opts, kp[:, :2] * scale, kp[:, 2],
                         box=tracks.bbox[r] * np.tile(scale, 2), score=tracks.score[r], track_id=pid,
                         empty_is_missing=True)
        frames.put(_Where(path), frame, [person], unique=False)
    return frames


def _pixel_csv(path: Path, opts: _Options) -> _Frames:
    """``frame,person,<joint>_x,<joint>_y,<joint>_s`` × 17 in pixels, optional ``x1,y1,x2,y2,score``.

    ``person`` orders the people of a frame (unique per frame); it is not a track identity. Empty cells
    are unknown (an empty keypoint is missing).
    """
    table = CsvTable.read(path, PIXEL_CSV_COLUMNS, optional=(*BOX_COLUMNS, "score"), ignore_case=True)
    frame = table.ints("frame") - (opts.frame_offset or 0)
    table.check_frames(frame, n_frames=opts.n_frames, unique=False)
    person = table.ints("person")
    table.check(duplicated(np.stack([frame, person], axis=1)), lambda i: f"duplicate person {person[i]} in "
                f"frame {frame[i]}", fix="keep one row per person and frame")
    kp = _csv_columns(table, KP_COLUMNS).reshape(-1, J, 3)
    box = _csv_columns(table, BOX_COLUMNS)
    score = _csv_columns(table, ("score",))[:, 0]
    frames = _Frames(path, opts)
    for r in np.lexsort((person, frame)).tolist():
        where = _Where(path, f"frame {frame[r]}, person {person[r]}", line=int(table.lines[r]))
        frames.put(where, int(frame[r]), [_person(where, opts, kp[r, :, :2], kp[r, :, 2], box=box[r],
                                                  score=score[r], empty_is_missing=True)], unique=False)
    return frames


def _csv_columns(table: CsvTable, columns: tuple[str, ...]) -> np.ndarray:
    """(N, len(columns)) floats, NaN where empty; all NaN when the file has none of the columns."""
    present = [c for c in columns if table.has(c)]
    if not present:
        return np.full((len(table), len(columns)), np.nan)
    if len(present) < len(columns):
        absent = [c for c in columns if c not in present]
        raise FormatError(table.path, f"has column(s) {present} but not {absent}", line=1,
                          fix=f"write all of {','.join(columns)} or none")
    return np.stack([table.floats(c, allow_empty=True) for c in columns], axis=1)  # (N, k), N = 0 too


_FRAME_READERS: dict[str, Callable[[object, _Where, _Options], list[_Person]]] = {
    "mmpose": _mmpose_frame,
    "openpose": _openpose_frame,
    "ultralytics": _ultralytics_frame,
}
"""Per-frame readers: one frame's JSON → people (per-frame folders)."""

_FILE_LOADERS: dict[str, Callable[[_Where, object, _Options], _Frames]] = {
    "mmpose": _load_mmpose,
    "coco": _load_coco,
    "openpose": _single_frame(_openpose_frame),
    "ultralytics": _load_ultralytics,
}
"""Whole-file loaders: parsed JSON → frames."""
