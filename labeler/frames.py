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

import numpy as np

from inference.clipio import Clip, FrameSource

from .viewer_common import encode_jpeg


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

    def get(self, index: int, scale: float = 1.0) -> bytes:
        """JPEG bytes of frame ``index`` (cached, or decoded and encoded now), at ``scale`` of its size
        (rounded up to eighths: the page asks for the pixels its view needs)."""
        index = int(index)
        if not 0 <= index < self.n_frames:
            raise IndexError(f"frame {index} is outside the clip (0..{self.n_frames - 1})")
        key = (index, eighths(scale))
        with self._lock:
            data = self._jpeg.get(key)
            if data is not None:
                self._jpeg.move_to_end(key)
                return data
        return self._load(key)

    def _load(self, key: tuple[int, int]) -> bytes:
        import cv2

        index, eighth = key
        with self._decode_lock:
            with self._lock:  # another thread may have produced it while we waited
                if key in self._jpeg:
                    return self._jpeg[key]
            rgb = self._source.read(index)
            if self.stamp:
                rgb = stamp_frame_number(rgb, index)
            if eighth < 8:
                h, w = rgb.shape[:2]
                rgb = cv2.resize(rgb, (max(16, round(w * eighth / 8)), max(16, round(h * eighth / 8))),
                                 interpolation=cv2.INTER_AREA)
            data = encode_jpeg(rgb, self.quality)
        with self._lock:
            self._jpeg[key] = data
            self._jpeg.move_to_end(key)
            while len(self._jpeg) > self.capacity:
                self._jpeg.popitem(last=False)
        return data

    def prefetch(self, index: int, direction: int = 1, scale: float = 1.0) -> None:
        """Queue the frames around ``index`` (``direction`` = +1 forward, -1 backward) for decoding."""
        step = 1 if direction >= 0 else -1
        wanted = [index + step * k for k in range(1, self.ahead + 1)]
        wanted += [index - step * k for k in range(1, self.behind + 1)]
        wanted = [i for i in wanted if 0 <= i < self.n_frames]
        eighth = eighths(scale)
        with self._wake:
            self._queue = deque((i, eighth) for i in wanted if (i, eighth) not in self._jpeg)
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
            try:
                self._load(key)
            except Exception:  # a broken frame is reported when it is actually asked for
                pass
