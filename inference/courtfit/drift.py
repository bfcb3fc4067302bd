"""Camera drift: does the court stay where the calibration puts it, all through the clip?

Broadcast "fixed" cameras creep (10–15 px over a rally is common). Every ``every_s`` seconds a frame's painted
lines are matched to the calibrated camera's projected court lines by the image shift that puts the
projected lines on the brightest line centres (whole working pixels within ±``max_shift_px``, then a
quarter-pixel grid). The report gives the shift per sampled frame and flags drift when
the shifts spread more than the calibration can explain.

Example:
    >>> report = measure_drift(Clip("clip"), camera, load_court("padel"))
    >>> report.max_drift_px, report.drifting, report.table()
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from inference.camera import Camera
from inference.court import Court

from .lines import LineEvidence, line_channel, line_mask, working_scale
from .model import court_line_samples

#: drift below this (px) is never reported, whatever the calibration's RMS
MIN_DRIFT_PX = 3.0
HIT_PX = 1.5  # working px


@dataclass
class DriftReport:
    """Per sampled frame, the image shift (full-resolution px) that best aligns the court lines.

    Attributes:
        frames: (F,) frame indices; shifts: (F, 2) dx, dy; support: (F,) share of the projected lines on
            line pixels after the shift (low: the court is hidden, a cut, a close-up).
        threshold_px: drift beyond this is reported (max of :data:`MIN_DRIFT_PX` and 2 × the calibration RMS).
    """

    frames: list[int]
    shifts: np.ndarray
    support: np.ndarray
    threshold_px: float
    fps: float
    notes: list[str] = field(default_factory=list)

    @property
    def valid(self) -> np.ndarray:
        """(F,) frames where the court was found well enough to measure a shift."""
        return self.support >= 0.3

    @property
    def max_drift_px(self) -> float:
        """The largest distance between the shifts of two valid frames (px)."""
        s = self.shifts[self.valid]
        if len(s) < 2:
            return 0.0
        return float(np.max(np.linalg.norm(s[:, None] - s[None], axis=2)))

    @property
    def drifting(self) -> bool:
        return self.max_drift_px > self.threshold_px

    def summary(self) -> str:
        v = self.valid
        text = (f"camera drift: {self.max_drift_px:.1f} px over {len(self.frames)} sampled frames "
                f"({int(v.sum())} with the court in view)")
        if self.drifting:
            text += (f" — beyond the calibration's {self.threshold_px:.1f} px: the camera moves during the clip; "
                     "3D positions far from the calibrated frames are off by about as much")
        if (~v).any():
            text += f"; court not found at frames {[f for f, ok in zip(self.frames, v) if not ok]} (a cut or close-up?)"
        return text

    def table(self) -> str:
        lines = ["frame   time_s    dx_px    dy_px  support"]
        for f, (dx, dy), s in zip(self.frames, self.shifts, self.support):
            lines.append(f"{f:5d}  {f / self.fps:7.2f}  {dx:7.2f}  {dy:7.2f}  {s:7.2f}")
        return "\n".join(lines + [self.summary()])


def _ridge_map(L: np.ndarray) -> np.ndarray:
    """(h, w) float32 line strength: brightness above the local background, smoothed (peaks at line centres)."""
    import cv2

    f = L.astype(np.float32)
    ridge = np.maximum(f - cv2.blur(f, (15, 15)), 0)
    return cv2.GaussianBlur(ridge, (0, 0), 1.0)


def frame_shift(frame: np.ndarray, samples: np.ndarray, max_shift_px: float = 24.0) -> tuple[np.ndarray, float]:
    """The (2,) shift (full px) that moves the projected court ``samples`` (P, 2) onto ``frame``'s painted
    lines, and the share of samples on line pixels after the shift.

    The line strength summed over the shifted samples is maximised on whole working pixels within
    ±``max_shift_px``, then on a quarter-pixel grid around the best (bilinear sampling)."""
    import cv2

    h, w = frame.shape[:2]
    scale = working_scale((w, h))
    L = line_channel(frame, scale)
    ridge = _ridge_map(L)
    hh, ww = ridge.shape
    p = ((samples + 0.5) * scale - 0.5).astype(np.float32)

    def strength(shifts: np.ndarray) -> np.ndarray:
        q = p[None] + shifts[:, None].astype(np.float32)  # (S, P, 2)
        v = cv2.remap(ridge, q[..., 0], q[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        return v.mean(axis=1)

    r = int(np.ceil(max_shift_px * scale))
    grid = np.stack(np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1)), -1).reshape(-1, 2).astype(float)
    best = grid[int(np.argmax(strength(grid)))]
    fine = best + np.stack(np.meshgrid(np.arange(-1, 1.01, 0.25), np.arange(-1, 1.01, 0.25)), -1).reshape(-1, 2)
    best = fine[int(np.argmax(strength(fine)))]
    ev = LineEvidence.from_mask(line_mask(L), scale, (w, h))
    q = np.round(p + best).astype(int)
    ok = (q[:, 0] >= 0) & (q[:, 0] < ww) & (q[:, 1] >= 0) & (q[:, 1] < hh)
    hits = float(np.sum(ev.distance[q[ok, 1], q[ok, 0]] <= HIT_PX))
    return best / scale, hits / max(len(samples), 1)


def measure_drift(clip, camera: Camera, court: Court, every_s: float = 1.0,
                  max_shift_px: float = 24.0, known: DriftReport | None = None) -> DriftReport:
    """Sample a frame every ``every_s`` seconds of ``clip`` (:class:`inference.clipio.Clip`) and measure its
    shift against ``camera``'s projected court lines (see the module docstring). Frames that ``known`` (an
    earlier report for the same clip, camera and ``max_shift_px``) measured are taken from it, not measured
    again."""
    from inference.video.masks import apply_mask, clip_mask

    fps = clip.info.fps
    n = clip.n_frames
    idx = list(range(0, n, max(1, int(round(every_s * fps)))))
    if idx[-1] != n - 1:
        idx.append(n - 1)
    samples = court_line_samples(camera, court)
    rms = camera.rms_px if camera.rms_px is not None else 0.0
    if not len(samples):  # no court line in the picture: nothing to measure against (every frame "not found")
        return DriftReport(idx, np.zeros((len(idx), 2)), np.zeros(len(idx)), max(MIN_DRIFT_PX, 2 * rms), fps)
    rects = clip_mask(clip)
    shifts, support = [], []
    done = {} if known is None else {f: (sh, sup) for f, sh, sup in zip(known.frames, known.shifts, known.support)}
    with clip.frames(cache_size=0) as src:
        for i in idx:
            s, sup = done[i] if i in done else frame_shift(apply_mask(src.read(i), rects), samples, max_shift_px)
            shifts.append(s)
            support.append(sup)
    return DriftReport(idx, np.array(shifts).reshape(-1, 2), np.array(support), max(MIN_DRIFT_PX, 2 * rms), fps)


# ------------------------------------------------------------------------------------ per-frame track
CAMERA_TRACK = "camera_track.csv"
TRACK_EVERY_S = 0.2


@dataclass
class CameraTrack:
    """The calibrated camera per frame, as an image shift: frame ``i``'s picture is the calibrated camera's
    moved by ``shift[i]`` px. For a "fixed" broadcast camera that pans or tilts by a fraction of a degree
    this is the whole change (a rotation of θ moves the picture by about f·θ; the perspective change is of
    second order); a camera that zooms or travels is not described.

    Attributes:
        shift: (N, 2) dx, dy px for every frame (linear between measured frames, held before the first and
            after the last). measured: (N,) bool frames where the court was matched.
    """

    shift: np.ndarray
    measured: np.ndarray

    def stabilise(self, uv: np.ndarray) -> np.ndarray:
        """(F, 2) pixels of frames 0..F-1 → where the calibrated camera sees the same points (``uv - shift``)."""
        uv = np.asarray(uv, float)
        n = min(len(uv), len(self.shift))
        out = uv.copy()
        out[:n] -= self.shift[:n]
        return out

    def write(self, path) -> None:
        from inference.clipio.csvtable import format_floats, format_ints, write_csv

        write_csv(path, ["frame", "dx_px", "dy_px", "measured"],
                  [format_ints(np.arange(len(self.shift))), format_floats(self.shift[:, 0], 3),
                   format_floats(self.shift[:, 1], 3), format_ints(self.measured.astype(int))])

    @classmethod
    def read(cls, path, n_frames: int) -> CameraTrack:
        """``camera_track.csv`` (one row per frame ``0 … n_frames-1``); FormatError naming the file and row."""
        from inference.clipio import FormatError
        from inference.clipio.csvtable import CsvTable

        t = CsvTable.read(path, ["frame", "dx_px", "dy_px", "measured"], allow_empty=False)
        frame = t.ints("frame")
        t.check_frames(frame, n_frames=n_frames)
        if len(frame) != n_frames or np.any(frame != np.arange(n_frames)):
            raise FormatError(path, f"needs one row per frame 0…{n_frames - 1} in order, has {len(frame)} rows",
                              fix="delete camera_track.csv and re-run rally3d infer or calibrate --drift")
        return cls(np.stack([t.floats("dx_px"), t.floats("dy_px")], axis=1), t.ints("measured") > 0)


def track_camera(clip, camera: Camera, court: Court, every_s: float = TRACK_EVERY_S,
                 max_shift_px: float = 24.0, known: DriftReport | None = None) -> tuple[CameraTrack, DriftReport]:
    """Match the court every ``every_s`` seconds (:func:`measure_drift`; the frames ``known`` measured already
    are reused) and interpolate the shift to every frame; frames where the court is not found (a cut, a
    close-up) are bridged from their neighbours.

    Raises:
        ValueError: the court was found in no sampled frame.
    """
    report = measure_drift(clip, camera, court, every_s=every_s, max_shift_px=max_shift_px, known=known)
    ok = report.valid
    if not ok.any():
        raise ValueError("the court's lines were found in no sampled frame: the camera cannot be tracked")
    f = np.asarray(report.frames)[ok]
    s = report.shifts[ok]
    frames = np.arange(clip.n_frames)
    shift = np.stack([np.interp(frames, f, s[:, 0]), np.interp(frames, f, s[:, 1])], axis=1)
    measured = np.zeros(clip.n_frames, bool)
    measured[f] = True
    return CameraTrack(shift, measured), report
