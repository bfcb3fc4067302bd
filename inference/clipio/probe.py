"""What a video file really holds, read from its container without decoding (PyAV): the frames' presentation
times, the stated frame rate and the field order.

Real footage is not always a tidy constant-rate progressive file: phones write **variable frame rate**
(irregular timestamps), broadcast recordings are often **interlaced** (1080i). :func:`probe_video_file` finds
both so that :class:`~inference.clipio.frames.VideoFrames` can present every video the same way: frames at
one constant rate (``i / fps`` is the time of frame ``i``), progressive.

* VFR → resampled to the stated rate: frame ``i`` is the source frame whose timestamp is nearest to
  ``t0 + i / fps`` (a gap repeats a frame, a burst drops frames), as ``ffmpeg -vsync cfr`` does.
* interlaced → deinterlaced by :func:`deinterlace` (the first field is kept, the other interpolated).

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
#: comb score (see :func:`comb_score`) above which a progressive-looking frame is taken as interlaced
COMB_THRESHOLD = 2.0


@dataclass(frozen=True)
class VideoProbe:
    """The container's view of a video file.

    Attributes:
        path: the file. codec, container: names as FFmpeg gives them.
        width, height: coded frame size (px).
        stated_fps: the rate the container states (average frame rate), None when it states none.
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
        """The rate to present the frames at: the stated one, unless it is far from the measured one."""
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
        (the nearest one in time; ties go to the earlier frame)."""
        t = self.times_s
        k = int(np.floor((t[-1] - t[0]) * fps + 0.5)) + 1
        grid = t[0] + np.arange(k) / fps
        j = np.clip(np.searchsorted(t, grid), 1, len(t) - 1)
        return np.where(grid - t[j - 1] <= t[j] - grid, j - 1, j).astype(np.int64)

    def timing_note(self, fps: float) -> str:
        """One line on how an irregular timing is presented (for the terminal and logs)."""
        m = self.cfr_map(fps)
        repeated = int(np.sum(np.diff(m) == 0))
        dropped = int(self.n_frames - len(np.unique(m)))
        d = self.intervals_s * 1000
        return (f"{self.path.name}: variable frame rate (frame intervals {d.min():.1f}–{d.max():.1f} ms): "
                f"resampled to a constant {fps:g} fps by nearest timestamp — {self.n_frames} frames → {len(m)} "
                f"({repeated} repeated, {dropped} dropped); frame i is at i / {fps:g} s")


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
            return VideoProbe(path, cc.name or "", name or "", int(cc.width), int(cc.height),
                              float(rate) if rate else None,
                              (np.sort(np.asarray(pts, np.float64)) - min(pts)) * tb if pts and tb
                              else np.zeros(0), field)
    except (av.FFmpegError, OSError, ValueError) as e:
        log.debug("PyAV cannot probe %s: %s", path, e)
        return None


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
