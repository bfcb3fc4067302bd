"""What a video file really holds, read from its container without decoding (PyAV): the frames' presentation
times, the stated frame rate and the field order.

Real footage is not always a tidy constant-rate progressive file: phones write **variable frame rate**
(irregular timestamps), broadcast recordings are often **interlaced** (1080i). :func:`probe_video_file` finds
both so that :class:`~inference.clipio.frames.VideoFrames` can present every video the same way: frames at
one constant rate (``i / fps`` is the time of frame ``i``), progressive.

* VFR → resampled to the **nominal** rate (:func:`nominal_rate`: the stream's ``r_frame_rate`` or guessed rate
  when it is a standard rate that the frames' spacing confirms, not the container's average rate, which
  dropped frames pull down: a 25 fps broadcast with dropped frames averages 21.5 fps): frame ``i`` is
  the source frame whose timestamp is nearest to ``t0 + i / fps`` (a gap repeats a frame, a burst drops
  frames), as ``ffmpeg -vsync cfr`` does. :class:`Resampling` says which.
* interlaced → deinterlaced by :func:`deinterlace` (the first field is kept, the other interpolated).
* **repeated pictures** on a regular beat (a 25 fps broadcast converted to a 30 fps file repeats every 6th
  picture; the timestamps are regular, the motion is not) → read at the content's rate, the repeats left out
  (:func:`find_picture_repeats`, :class:`PictureRepeats`): at 30 fps a ball seems to stop for a frame every
  0.2 s and to move 20 % faster in between, which no flight fits.

Example:
    >>> p = probe_video_file("match.mkv")
    >>> p.vfr, p.interlaced, p.cfr_map(30.0)[:5]
"""
from __future__ import annotations

import functools
import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger(__name__)

#: FFmpeg's AVFieldOrder codes (PyAV gives the number) → ffprobe's names
FIELD_ORDERS = {0: "unknown", 1: "progressive", 2: "tt", 3: "bb", 4: "tb", 5: "bt"}
#: an interval between two frames more than this fraction off the median makes the timing irregular
VFR_TOLERANCE = 0.25
#: the usual camera and broadcast rates (frames/s); NTSC's are 1000/1001 of the round ones
STANDARD_RATES = (15.0, 24000 / 1001, 24.0, 25.0, 30000 / 1001, 30.0, 48.0, 50.0, 60000 / 1001, 60.0, 90.0,
                  100.0, 120000 / 1001, 120.0, 240.0)
#: a rate within this fraction of a standard one is that rate (``2997/100`` is 29.97 fps)
RATE_MATCH = 0.002
#: a rate measured from the frames' spacing is snapped to a standard one this close (millisecond timestamps)
SPACING_MATCH = 0.03
#: two timestamps this close (s) are as near a grid time as each other (the time bases' rounding)
TIE_S = 1e-6
#: frame indices listed in notes and clip.yaml's ``timing`` (the counts are always complete)
FIRST_FEW = 10
#: comb score (see :func:`comb_score`) above which a progressive-looking frame is taken as interlaced
COMB_THRESHOLD = 2.0


@dataclass(frozen=True)
class VideoProbe:
    """The container's view of a video file.

    Attributes:
        path: the file. codec, container: names as FFmpeg gives them.
        width, height: coded frame size (px).
        stated_fps: the rate the container states (average frame rate), None when it states none.
        nominal_fps: the stream's nominal rate (:func:`nominal_rate`), None when none is standard.
        times_s: (N,) presentation time of every frame, sorted, seconds from the first frame.
        field_order: ``progressive``, ``tt``, ``bb``, ``tb``, ``bt`` (interlaced) or ``unknown``.
    """

    path: Path
    codec: str
    container: str
    width: int
    height: int
    stated_fps: float | None
    times_s: np.ndarray
    field_order: str
    nominal_fps: float | None = None

    @property
    def n_frames(self) -> int:
        return len(self.times_s)

    @property
    def measured_fps(self) -> float | None:
        """Frames per second over the file's duration (None with fewer than two frames)."""
        span = float(self.times_s[-1] - self.times_s[0]) if self.n_frames > 1 else 0.0
        return (self.n_frames - 1) / span if span > 0 else None

    @property
    def fps(self) -> float | None:
        """The rate to present the frames at: the nominal one when there is one, else the stated (average)
        one, unless it is far from the measured one."""
        if self.nominal_fps:
            return self.nominal_fps
        m, s = self.measured_fps, self.stated_fps
        if s and (m is None or 0.5 * m <= s <= 2.0 * m):
            return s
        return m or s

    @property
    def interlaced(self) -> bool:
        return self.field_order in ("tt", "bb", "tb", "bt")

    @property
    def intervals_s(self) -> np.ndarray:
        return np.diff(self.times_s)

    @property
    def vfr(self) -> bool:
        """The frames' timestamps are irregular (an interval more than 25 % off the nominal one)."""
        d = self.intervals_s
        if len(d) < 2 or not self.fps:
            return False
        return bool(np.any(np.abs(d * self.fps - 1.0) > VFR_TOLERANCE))

    def cfr_map(self, fps: float) -> np.ndarray:
        """(K,) source frame shown at each frame of a constant ``fps`` grid from the first to the last timestamp
        (the nearest one in time; ties, within :data:`TIE_S`, go to the earlier frame)."""
        t = self.times_s
        k = int(np.floor((t[-1] - t[0]) * fps + 0.5)) + 1
        grid = t[0] + np.arange(k) / fps
        j = np.clip(np.searchsorted(t, grid), 1, len(t) - 1)
        return np.where(grid - t[j - 1] <= t[j] - grid + TIE_S, j - 1, j).astype(np.int64)

    def resampling(self, fps: float) -> Resampling:
        """How the frames are presented at a constant ``fps`` (:meth:`cfr_map`)."""
        return Resampling(self.path.name, float(fps), self.stated_fps, self.n_frames, self.cfr_map(fps),
                          self.intervals_s)

    def timing_note(self, fps: float) -> str:
        """One line on how an irregular timing is presented (for the terminal and logs)."""
        return self.resampling(fps).note()


@dataclass(frozen=True)
class Resampling:
    """A variable-frame-rate video presented at a constant rate.

    Attributes:
        name: the file's name. fps: the constant rate. average_fps: the container's average rate.
        n_source: frames in the file. source: (K,) the file's frame shown at each clip frame.
        intervals_s: (n_source - 1,) the file's frame intervals.
    """

    name: str
    fps: float
    average_fps: float | None
    n_source: int
    source: np.ndarray
    intervals_s: np.ndarray

    @property
    def repeated(self) -> np.ndarray:
        """Clip frames that show the same picture as the frame before (a gap in the file's timestamps)."""
        return np.flatnonzero(np.diff(self.source) == 0) + 1

    @property
    def dropped(self) -> np.ndarray:
        """The file's frames that no clip frame shows (a burst of timestamps)."""
        return np.setdiff1d(np.arange(self.n_source), self.source)

    def record(self, first: int = 0, stop: int | None = None) -> dict:
        """clip.yaml's ``timing`` for clip frames ``first .. stop-1`` (renumbered from 0): the counts and the
        first :data:`FIRST_FEW` frames repeated (clip frames) and dropped (the file's frames)."""
        stop = len(self.source) if stop is None else stop
        rep = self.repeated
        rep = rep[(rep > first) & (rep < stop)] - first
        drop = self.dropped
        if first > 0 or stop < len(self.source):
            drop = drop[(drop > self.source[first]) & (drop < self.source[stop - 1])]
        out = {"variable_frame_rate": True, "fps": self.fps, "source_frames": self.n_source,
               "repeated": len(rep), "repeated_frames": rep[:FIRST_FEW].tolist(),
               "dropped": len(drop), "dropped_source_frames": drop[:FIRST_FEW].tolist()}
        if self.average_fps:
            out["average_fps"] = round(float(self.average_fps), 3)
        return out

    def note(self) -> str:
        """One line for the terminal and logs: the rates, the counts, the first frames repeated and dropped."""
        d = self.intervals_s * 1000
        spread = f"frame intervals {d.min():.1f}–{d.max():.1f} ms" if len(d) else "one frame"
        avg = self.average_fps
        average = f"; the container's average {avg:.2f} fps is not used" \
            if avg and abs(avg / self.fps - 1) > RATE_MATCH else ""
        rep, drop = self.repeated, self.dropped
        return (f"{self.name}: variable frame rate ({spread}{average}): resampled to a constant "
                f"{self.fps:g} fps by nearest timestamp — {self.n_source} frames → {len(self.source)} "
                f"({len(rep)} repeated{_first(rep, 'frames')}; {len(drop)} dropped"
                f"{_first(drop, 'source frames')}); frame i is at i / {self.fps:g} s")


def _first(indices: np.ndarray, what: str) -> str:
    """``: frames 3, 9, …`` listing the first :data:`FIRST_FEW` of ``indices`` ("" when none)."""
    if not len(indices):
        return ""
    more = ", …" if len(indices) > FIRST_FEW else ""
    return f": {what} " + ", ".join(str(int(i)) for i in indices[:FIRST_FEW]) + more


def standard_rate(rate: float | None, tolerance: float = RATE_MATCH) -> float | None:
    """The :data:`STANDARD_RATES` entry within ``tolerance`` (relative) of ``rate``, else None."""
    if not rate or not np.isfinite(rate) or rate <= 0:
        return None
    best = min(STANDARD_RATES, key=lambda r: abs(rate / r - 1))
    return best if abs(rate / best - 1) <= tolerance else None


def nominal_rate(candidates: list[float | None], times_s: np.ndarray) -> float | None:
    """The rate the frames were filmed at, whatever frames are missing or doubled.

    The first of ``candidates`` (the stream's ``r_frame_rate``, then its guessed rate) that is a standard rate
    and that the typical frame interval confirms (within :data:`VFR_TOLERANCE`); else, when the intervals are
    irregular, the typical interval's rate if it is close to a standard one (:data:`SPACING_MATCH`:
    millisecond timestamps jitter); else None. The typical interval is the mean of the intervals near the
    median one, so gaps and bursts do not count.
    """
    d = np.diff(np.asarray(times_s, np.float64))
    d = d[d > 0]
    period = None
    if len(d):
        med = float(np.median(d))
        period = float(np.mean(d[np.abs(d / med - 1) <= VFR_TOLERANCE]))
    for rate in candidates:
        if standard_rate(rate) and (period is None or abs(period * float(rate) - 1) <= VFR_TOLERANCE):
            return float(rate)
    if period is None or not np.any(np.abs(d / period - 1) > VFR_TOLERANCE):
        return None  # regular frames at an unusual rate: the container's rate stands
    snapped = standard_rate(1 / period, SPACING_MATCH)
    return float(snapped) if snapped else None


def _probe(path: Path) -> VideoProbe | None:
    try:
        import av
    except ImportError:  # pragma: no cover - PyAV is a dependency
        return None
    try:
        with av.open(str(path)) as container:
            if not container.streams.video:
                return None
            stream = container.streams.video[0]
            cc = stream.codec_context
            rate = stream.average_rate or stream.guessed_rate
            pts = [p.pts for p in container.demux(stream) if p.pts is not None and p.size > 0]
            tb = float(stream.time_base) if stream.time_base else 0.0
            field = cc.field_order
            field = FIELD_ORDERS.get(int(field), "unknown") if not isinstance(field, str) else field
            name = container.format.name
            times = (np.sort(np.asarray(pts, np.float64)) - min(pts)) * tb if pts and tb else np.zeros(0)
            nominal = nominal_rate([_rate(stream.base_rate), _rate(stream.guessed_rate)], times)
            return VideoProbe(path, cc.name or "", name or "", int(cc.width), int(cc.height),
                              float(rate) if rate else None, times, field, nominal)
    except (av.FFmpegError, OSError, ValueError) as e:
        log.debug("PyAV cannot probe %s: %s", path, e)
        return None


def _rate(value) -> float | None:
    """A PyAV rate (a Fraction or None) as a float; None when absent or zero."""
    return float(value) if value else None


@functools.lru_cache(maxsize=32)
def _probe_cached(path: str, size: int, mtime_ns: int) -> VideoProbe | None:
    return _probe(Path(path))


def probe_video_file(path: str | Path) -> VideoProbe | None:
    """Probe ``path`` (demuxing only: a few ms per minute of 1080p); None when PyAV cannot read it or it has
    no timestamps (the OpenCV reader then decides). Cached per file version."""
    path = Path(path)
    try:
        st = os.stat(path)
    except OSError:
        return None
    p = _probe_cached(str(path.resolve()), st.st_size, st.st_mtime_ns)
    return p if p is not None and p.n_frames > 0 else None


# ------------------------------------------------------------------------------------ repeated pictures
#: a frame whose difference from the one before is below this share of the median difference repeats it
REPEAT_SHARE = 0.2
#: frames decoded (at low resolution) to look for repeated pictures
REPEAT_SCAN = 360


@dataclass(frozen=True)
class PictureRepeats:
    """Content at a lower rate in a higher-rate file: every ``period``-th frame (from ``phase``) repeats the
    picture before it (25 fps in 30 fps: period 6; 24 in 30: 5; 25 in 50: 2).

    Attributes:
        period: frames per beat; phase: the first repeated frame (a file frame index, ≥ 1).
        file_fps: the file's rate. found: repeats seen in the frames scanned; scanned: frames scanned.
    """

    period: int
    phase: int
    file_fps: float
    found: int = 0
    scanned: int = 0

    def __post_init__(self) -> None:
        if not (2 <= int(self.period) <= 60) or not (1 <= int(self.phase)) or not self.file_fps > 0:
            raise ValueError(f"picture repeats need period 2-60, phase >= 1 and a positive rate, got {self}")

    @property
    def content_fps(self) -> float:
        """The rate of the pictures (the file's rate less the repeats)."""
        return self.file_fps * (self.period - 1) / self.period

    def keep(self, n: int) -> np.ndarray:
        """(K,) the file's frames that show a new picture, of its first ``n``."""
        i = np.arange(n)
        return i[(i < self.phase) | ((i - self.phase) % self.period != 0)]

    def record(self) -> dict:
        """clip.yaml's ``timing.repeated_pictures``."""
        return {"period": int(self.period), "phase": int(self.phase), "file_fps": round(float(self.file_fps), 4),
                "content_fps": round(float(self.content_fps), 4)}

    @classmethod
    def from_record(cls, d) -> PictureRepeats | None:
        """From clip.yaml's ``timing.repeated_pictures`` (None when absent or malformed)."""
        try:
            return cls(int(d["period"]), int(d["phase"]), float(d["file_fps"]))
        except (KeyError, TypeError, ValueError):
            return None

    def note(self, name: str) -> str:
        return (f"{name}: every {self.period}th frame repeats the picture before it ({self.found} of "
                f"{self.scanned} frames scanned, from frame {self.phase}): {self.content_fps:g} fps content in "
                f"a {self.file_fps:g} fps file, read at {self.content_fps:g} fps with the repeats left out")


def repeat_pattern(diffs: np.ndarray, fps: float) -> tuple[int, int, int] | None:
    """``(period, phase, repeats found)`` of the frames that repeat the one before on a regular beat, from the
    (N-1,) mean absolute differences of consecutive frames (``diffs[i]``: frame i+1 against frame i); None
    when there is no such beat (a still picture, irregular repeats) or the content rate it gives is no
    standard rate."""
    d = np.asarray(diffs, float)
    moving = d[d > 0]
    if len(d) < 12 or not len(moving):
        return None
    typical = float(np.median(d))
    if typical < 0.05:  # a still picture: nothing to tell a repeat by
        return None
    rep = np.flatnonzero(d < REPEAT_SHARE * typical) + 1
    if len(rep) < 4 or len(rep) > 0.55 * len(d):
        return None
    gaps = np.diff(rep)
    period = int(np.bincount(gaps).argmax()) if len(gaps) else 0
    if not 2 <= period <= 12 or np.mean(gaps % period == 0) < 0.8 or np.mean(gaps == period) < 0.5:
        return None
    phases = np.bincount(rep % period, minlength=period)
    phase_mod = int(phases.argmax())
    if phases[phase_mod] < 0.8 * len(rep):
        return None
    expected = np.arange(phase_mod if phase_mod else period, len(d) + 1, period)
    if np.mean(np.isin(expected, rep)) < 0.6:  # most beats of the scan repeat (not a few still moments)
        return None
    if standard_rate(fps * (period - 1) / period, 0.01) is None:
        return None
    return period, int(rep[np.isin(rep % period, phase_mod)][0] % period or period), int(len(rep))


def find_picture_repeats(path: str | Path, fps: float | None = None, scan: int = REPEAT_SCAN
                         ) -> PictureRepeats | None:
    """Decode the first ``scan`` frames of a video at low resolution and find a regular beat of repeated
    pictures (:func:`repeat_pattern`); None when there is none. About 1 s per 360 frames of 1080p."""
    import cv2

    cap = cv2.VideoCapture(str(path))
    try:
        fps = fps or cap.get(cv2.CAP_PROP_FPS) or None
        diffs, prev = [], None
        for _ in range(scan):
            ok, bgr = cap.read()
            if not ok or bgr is None:
                break
            g = cv2.cvtColor(cv2.resize(bgr, (160, 90), interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2GRAY)
            g = g.astype(np.float32)
            if prev is not None:
                diffs.append(float(np.abs(g - prev).mean()))
            prev = g
    finally:
        cap.release()
    if not fps:
        return None
    found = repeat_pattern(np.array(diffs), float(fps))
    if found is None:
        return None
    period, phase, n = found
    return PictureRepeats(period, phase, float(fps), n, len(diffs) + 1)


# ------------------------------------------------------------------------------------------ interlace
def comb_score(frame: np.ndarray) -> float:
    """How combed ``frame`` (H, W, 3) looks: the lines' difference from their neighbours in the other field
    over the difference from the neighbours two lines away (same field), on the rows that differ at all.
    About 1 for progressive images; ≫ 1 when the two fields show different moments (motion in 1080i)."""
    g = frame.mean(axis=2) if frame.ndim == 3 else frame.astype(np.float64)
    mid = g[2:-2]
    other = np.abs(2 * mid - g[1:-3] - g[3:-1])  # neighbours from the other field
    same = np.abs(2 * mid - g[:-4] - g[4:])  # neighbours from the same field
    moving = (other > 20) | (same > 20)
    if moving.sum() < 50:
        return 1.0
    return float(other[moving].mean() / max(same[moving].mean(), 1.0))


def deinterlace(frame: np.ndarray, field_order: str) -> np.ndarray:
    """Keep the first field of ``frame`` (H, W, 3) and interpolate the other's lines from it (line average).

    No combing is left; vertical detail halves and the frame rate stays (1080i50 → 25 frames/s).
    ``field_order`` ``tt``/``tb``: the top field (even lines) comes first; ``bb``/``bt``: the bottom field."""
    out = frame.copy()
    keep = 1 if field_order in ("bb", "bt") else 0
    h = frame.shape[0]
    f = frame.astype(np.uint16)
    rows = np.arange(1 - keep, h, 2)  # lines of the dropped field
    above = np.clip(rows - 1, keep, None)
    below = np.where(rows + 1 < h, rows + 1, rows - 1)
    out[rows] = ((f[above] + f[below] + 1) // 2).astype(np.uint8)
    return out
