"""Frames for the browser: decode, JPEG-encode, cache and prefetch around the frames being looked at.

One :class:`FrameCache` per clip, shared by every tab on it. ``get(i)`` returns the JPEG bytes of frame ``i``
(decoding and encoding it when not cached); :meth:`FrameCache.prefetch` queues the frames the annotator is
likely to ask for next (ahead in the stepping direction first, a few behind), which a background thread
decodes while the annotator looks at the current one. Sequential decoding of a video is cheap; seeking
backwards in H.264 is not, so the cache keeps a window on both sides.
"""
from __future__ import annotations

import math
import threading
from collections import OrderedDict, deque
from collections.abc import Sequence

import numpy as np

from inference.clipio import Clip, FrameSource
from inference.clipio.frames import MAX_GRAB_AHEAD

from .viewer_common import encode_jpeg


SERVE_WINDOW = 16
"""Frames :meth:`FrameCache.next_to_serve` chooses among (the most wanted ones)."""

BACKWARD_RUN = 32
"""Frames decoded below a frame asked for backwards that needs a seek (one seek for them all: a backward seek
in H.264 decodes from the previous key frame)."""

FRAME_CODE_BITS = 16
"""Bits of the frame code burned under the number (frames 0..65535)."""


def frame_code_layout(width: int) -> tuple[int, int, int]:
    """``(x0, y0, cell)``: where the frame code's first cell starts in a ``width``-pixel-wide frame, and the
    cell size (px). The cells run right from ``x0``; cell ``k`` (``k = 0`` the most significant bit) is white
    for a 1, black for a 0. The size grows with the frame so that a cell stays ≥ 5 screen pixels when the
    whole frame is fitted into a browser canvas."""
    scale = max(0.4, width / 1600)
    cell = max(4, int(round(width / 200)))
    pad = int(4 * scale) + 2
    th = int(round(22 * scale)) + 2 * pad
    return pad, th, cell


def code_cell_centres(width: int) -> np.ndarray:
    """``(FRAME_CODE_BITS, 2)`` pixel centres of the frame code's cells (see :func:`frame_code_layout`)."""
    x0, y0, cell = frame_code_layout(width)
    k = np.arange(FRAME_CODE_BITS)
    return np.stack([x0 + (k + 0.5) * cell, np.full(len(k), y0 + 0.5 * cell)], axis=1)


def read_frame_code(levels: np.ndarray) -> int:
    """The frame number from the grey levels ``(FRAME_CODE_BITS,)`` sampled at :func:`code_cell_centres`."""
    bits = (np.asarray(levels, float) > 127).astype(int)
    return int(sum(int(b) << (FRAME_CODE_BITS - 1 - k) for k, b in enumerate(bits)))


def stamp_frame_number(rgb: np.ndarray, index: int) -> np.ndarray:
    """A copy of ``rgb (H, W, 3)`` with ``#index`` and its binary code in a dark box at its top-left corner.

    The number travels with the picture, so what the annotator reads is the frame on screen even while the
    browser is still decoding the next one (the status line may already name it). The code under it
    (:func:`code_cell_centres`, :func:`read_frame_code`) lets a test or benchmark read the frame on screen
    from the canvas pixels.
    """
    import cv2

    img = np.array(rgb, copy=True)
    h, w = img.shape[:2]
    scale = max(0.4, w / 1600)
    thick = max(1, int(round(scale * 2)))
    text = f"#{index}"
    (tw, th), base = cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, thick)
    x0, y0, cell = frame_code_layout(w)
    pad = x0
    img[: y0 + cell + pad, : max(tw, FRAME_CODE_BITS * cell) + 2 * pad] //= 4
    cv2.putText(img, text, (pad, pad + th), cv2.FONT_HERSHEY_SIMPLEX, scale, (255, 255, 255), thick, cv2.LINE_AA)
    value = int(index) % (1 << FRAME_CODE_BITS)
    for k in range(FRAME_CODE_BITS):
        bit = (value >> (FRAME_CODE_BITS - 1 - k)) & 1
        img[y0: y0 + cell, x0 + k * cell: x0 + (k + 1) * cell] = 255 if bit else 0
    return img


def serve_next(frames: Sequence[int], ready: set[int], free: set[int], *, first: bool = False) -> int:
    """The frame of ``frames`` (most wanted first, at least one) to produce next without seeking the video
    back and forth: the first one already ``ready``, else the lowest one on the decoder's way to the most
    wanted one (``free``: reached without a seek), else, when the most wanted one needs a seek, the lowest
    one up to :data:`~inference.clipio.frames.MAX_GRAB_AHEAD` frames below it, so that one seek serves them
    all in ascending order (a backward seek in H.264 decodes from the previous key frame: playing backwards
    frame by frame would pay it for every frame). ``first``: the most wanted frame whatever it costs (an
    annotator is waiting for it). Only the first :data:`SERVE_WINDOW` frames are considered."""
    cands = list(frames[:SERVE_WINDOW])
    top = cands[0]
    if first:
        return top
    for f in cands:
        if f in ready:
            return f
    if top in free:
        return min(f for f in cands if f in free and f <= top)
    return min(f for f in cands if top - MAX_GRAB_AHEAD <= f <= top)


def eighths(scale: float) -> int:
    """A share of the full frame size (0, 1] as eighths, rounded up (1..8)."""
    return int(min(8, max(1, math.ceil(float(scale) * 8 - 1e-6))))


class FrameCache:
    """JPEG frames of one clip with an LRU cache and a prefetch thread.

    Args:
        clip: the clip.
        quality: JPEG quality (85: ≈100–200 KiB per 720p frame).
        capacity: frames kept (JPEG bytes, so 64 frames ≈ 10 MiB at 720p).
        ahead, behind: frames prefetched in the stepping direction and against it.
        prefetch: run the background thread (off for measuring cold decodes).
        stamp: burn the frame number into each frame (:func:`stamp_frame_number`).
    """

    def __init__(self, clip: Clip, *, quality: int = 85, capacity: int = 96, ahead: int = 12, behind: int = 4,
                 prefetch: bool = True, stamp: bool = True):
        self.clip = clip
        self.quality = int(quality)
        self.stamp = bool(stamp)
        self.capacity = int(capacity)
        self.ahead, self.behind = int(ahead), int(behind)
        self.n_frames = int(clip.n_frames)
        self._source: FrameSource = clip.frames(cache_size=0)
        self._decode_lock = threading.Lock()
        self._lock = threading.Lock()
        self._jpeg: OrderedDict[tuple[int, int], bytes] = OrderedDict()  # (frame, eighths of full size)
        self._queue: deque[tuple[int, int]] = deque()
        self._backward = False  # the queue runs backwards (see :meth:`get`)
        self._wake = threading.Condition(self._lock)
        self._stopped = False
        self._thread = None
        if prefetch:
            self._thread = threading.Thread(target=self._worker, name=f"prefetch-{clip.root.name}", daemon=True)
            self._thread.start()

    def close(self) -> None:
        with self._wake:
            self._stopped = True
            self._wake.notify_all()
        if self._thread is not None:
            self._thread.join(timeout=2)
        with self._decode_lock:
            self._source.close()

    def cached(self, index: int, scale: float = 1.0) -> bool:
        with self._lock:
            return (int(index), eighths(scale)) in self._jpeg

    def get(self, index: int, scale: float = 1.0, *, backward: int = 0) -> bytes:
        """JPEG bytes of frame ``index`` (cached, or decoded and encoded now), at ``scale`` of its size
        (rounded up to eighths: the page asks for the pixels its view needs). ``backward`` > 0: the frames
        are being asked for in descending order (playing or stepping backwards): when this one needs a seek,
        the ``backward`` frames below it are decoded in the same pass and kept (see :data:`BACKWARD_RUN`)."""
        index = int(index)
        if not 0 <= index < self.n_frames:
            raise IndexError(f"frame {index} is outside the clip (0..{self.n_frames - 1})")
        key = (index, eighths(scale))
        with self._lock:
            data = self._jpeg.get(key)
            if data is not None:
                self._jpeg.move_to_end(key)
                return data
        return self._load(key, max(0, int(backward)))

    def next_to_serve(self, frames: Sequence[int], scale: float = 1.0, *, first: bool = False) -> int:
        """Which of ``frames`` (most wanted first) to encode and send next: :func:`serve_next` with this
        cache's encoded frames at ``scale`` and its decoder's position."""
        cands = [int(f) for f in frames[:SERVE_WINDOW] if 0 <= int(f) < self.n_frames]
        if not cands:
            raise ValueError("no frame to serve")
        eighth = eighths(scale)
        with self._lock:
            ready = {f for f in cands if (f, eighth) in self._jpeg}
        with self._decode_lock:
            free = {f for f in cands if self._source.seek_free(f)}
        return serve_next(cands, ready, free, first=first)

    def _load(self, key: tuple[int, int], run: int = 0) -> bytes:
        """Decode and encode ``key`` = (frame, eighths); with ``run`` > 0 (going backwards) and a seek needed,
        the ``run`` frames below it first, in one pass, kept too (they are the next ones asked for)."""
        index, eighth = key
        with self._decode_lock:
            with self._lock:  # another thread may have produced it while we waited
                if key in self._jpeg:
                    return self._jpeg[key]
            if run > 0 and not self._source.seek_free(index):
                for below in range(max(0, index - run), index):
                    with self._lock:
                        done = (below, eighth) in self._jpeg
                    if not done:
                        self._store((below, eighth), self._encode(below, eighth))
            data = self._encode(index, eighth)
        self._store(key, data)
        return data

    def _encode(self, index: int, eighth: int) -> bytes:
        """Frame ``index`` decoded, stamped, resized to ``eighth`` eighths and JPEG-encoded (call holding the
        decode lock)."""
        import cv2

        rgb = self._source.read(index)
        if self.stamp:
            rgb = stamp_frame_number(rgb, index)
        if eighth < 8:
            h, w = rgb.shape[:2]
            # area averaging where it matters (a half or less: thin lines would flicker); bilinear, seven
            # times faster at 1080p, for the mild reductions of a fitted view
            rgb = cv2.resize(rgb, (max(16, round(w * eighth / 8)), max(16, round(h * eighth / 8))),
                             interpolation=cv2.INTER_AREA if eighth <= 4 else cv2.INTER_LINEAR)
        return encode_jpeg(rgb, self.quality)

    def _store(self, key: tuple[int, int], data: bytes) -> None:
        with self._lock:
            self._jpeg[key] = data
            self._jpeg.move_to_end(key)
            while len(self._jpeg) > self.capacity:
                self._jpeg.popitem(last=False)

    def prefetch(self, index: int, direction: int = 1, scale: float = 1.0) -> None:
        """Queue the frames around ``index`` (``direction`` = +1 forward, -1 backward) for decoding."""
        step = 1 if direction >= 0 else -1
        wanted = [index + step * k for k in range(1, self.ahead + 1)]
        wanted += [index - step * k for k in range(1, self.behind + 1)]
        wanted = [i for i in wanted if 0 <= i < self.n_frames]
        eighth = eighths(scale)
        with self._wake:
            self._queue = deque((i, eighth) for i in wanted if (i, eighth) not in self._jpeg)
            self._backward = step < 0
            self._wake.notify_all()

    def _worker(self) -> None:
        while True:
            with self._wake:
                while not self._queue and not self._stopped:
                    self._wake.wait()
                if self._stopped:
                    return
                key = self._queue.popleft()
                if key in self._jpeg:
                    continue
                run = BACKWARD_RUN if self._backward else 0
            try:
                self._load(key, run)
            except Exception:  # a broken frame is reported when it is actually asked for
                pass
