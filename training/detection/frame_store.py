"""The ball detectors' frame store: a clip's letterboxed frames as JPEG (or PNG), one indexed file per clip.

The training windows need the frames of a clip at network size (e.g. 288×512). Decoding the video for every
window would be slow (seeking in H.264 means decoding from the last key frame), and keeping every frame as
raw ``uint8`` costs 442 kB per 288×512 frame (45 GB for an hour of 30 fps video). The store keeps each
letterboxed frame as one JPEG (about 45 kB at quality 95, 4:2:0), written once beside the data, and decodes
the frames a window needs in ``__getitem__`` (about 0.8 ms a frame), so DataLoader workers decode in
parallel. The splits that are scored (validation, test) use ``codec="png"``: lossless (about 160 kB and
3.5 ms a frame), so their F1 is the F1 of eval.py and of inference on the video.
A small per-process LRU (:data:`LRU`, 64 MB by default) keeps the frames decoded last: overlapping windows
(``step`` < ``frames_in``) decode each frame once. Measured against the old raw cache by
``bench/bench_data_path.py`` (docs/benchmarks.md).

File layout (one ``.npy`` file: a 1-D ``uint8`` array, so ``np.load(path, mmap_mode="r")`` maps it):

* head (32 bytes): ``MAGIC``, format version, codec (JPEG or PNG), JPEG quality, chroma subsampling, frame
  count, height, width;
* the encoded bytes of every frame, one after another;
* the index: ``n + 1`` byte offsets (int64) and ``n`` CRC-32 checksums (uint32) of the frames' bytes;
* tail (16 bytes): the index's position and ``MAGIC`` again.

:class:`FrameStore` checks the layout when it opens a file (a truncated or foreign file raises
:class:`StoreError`: the caller rebuilds it) and each frame's checksum when it decodes it (a damaged frame
raises :class:`~inference.clipio.FormatError` naming the file and the fix: delete it).

Example::

    with StoreWriter(path, (288, 512)) as w:
        for frame in frames:            # (288, 512, 3) uint8 RGB
            w.add(frame)
    store = FrameStore(path)
    window = store[10:13]               # (3, 288, 512, 3) uint8
"""
from __future__ import annotations

import io
import os
import struct
import threading
import zlib
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from collections.abc import Iterable
from pathlib import Path

import cv2
import numpy as np

from inference.clipio import FormatError

DECODE_THREADS = max(1, int(os.environ.get("RALLY3D_FRAME_THREADS", 3)))
"""Threads per process that decode a window's frames side by side (``RALLY3D_FRAME_THREADS`` changes it)."""
MAGIC = b"R3DJPEG\x00"
VERSION = 1
QUALITY = 95
"""JPEG quality of new stores: the shipped WASB finds the ball on 347 of 429 frames from a quality-95 store
against 361 from the raw frames, 311 at quality 90 (docs/training.md#the-frame-store, bench_data_path.py)."""
SUBSAMPLING = "420"
"""Chroma subsampling of new stores: ``420`` (JPEG's usual; the source videos are 4:2:0 too) or ``444``."""
_HEAD = struct.Struct("<8sHBBBIHH11x")  # magic, version, codec, quality, subsampling (1: 4:4:4), n, H, W
CODECS = ("jpeg", "png")
_TAIL = struct.Struct("<Q8s")           # index position (bytes from the start of the body), magic
_NPY_HEADER_BYTES = 128
_RGB = getattr(cv2, "IMREAD_COLOR_RGB", None)  # OpenCV >= 4.10 decodes straight to RGB


def store_tag(codec: str = "jpeg", quality: int | None = None, subsampling: str | None = None) -> str:
    """What the cache key of a store includes, so a change of codec, format or quality makes a new file."""
    if codec == "png":
        return f"png{VERSION}"
    return f"jpeg{VERSION}-q{quality or QUALITY}-{subsampling or SUBSAMPLING}"


def encode_frame(frame: np.ndarray, codec: str = "jpeg", quality: int | None = None,
                 subsampling: str | None = None) -> bytes:
    """An RGB ``uint8 (H, W, 3)`` frame as the store writes it: JPEG (default :data:`QUALITY`,
    :data:`SUBSAMPLING`) or PNG (lossless; fast compression)."""
    if codec == "png":
        params = [cv2.IMWRITE_PNG_COMPRESSION, 1, cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_RLE]
    else:
        params = [cv2.IMWRITE_JPEG_QUALITY, int(quality or QUALITY)]
        if (subsampling or SUBSAMPLING) == "444":
            params += [cv2.IMWRITE_JPEG_SAMPLING_FACTOR, cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444]
    ok, buf = cv2.imencode(".png" if codec == "png" else ".jpg", np.ascontiguousarray(frame[..., ::-1]),
                           params)  # OpenCV encodes BGR
    if not ok:
        raise OSError(f"{codec} encoding of a {frame.dtype} {frame.shape} frame failed")
    return buf.tobytes()


def decode_frame(buf) -> np.ndarray | None:
    """JPEG or PNG bytes (any buffer) → RGB ``uint8 (H, W, 3)``, None when they do not decode."""
    buf = np.frombuffer(buf, np.uint8)
    if _RGB is not None:
        return cv2.imdecode(buf, _RGB)
    frame = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    return None if frame is None else cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)


class StoreError(ValueError):
    """A store file is not a complete frame store (truncated, foreign, older format): rebuild it."""


class FrameLRU:
    """Decoded frames kept per process, least recently used dropped first, up to ``max_bytes``
    (0 turns it off). Keys are (store identity, frame index); frames are read-only."""

    def __init__(self, max_bytes: int):
        self.max_bytes = int(max_bytes)
        self._frames: OrderedDict[tuple, np.ndarray] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()
        self.hits = self.misses = 0

    def get(self, key: tuple) -> np.ndarray | None:
        with self._lock:
            frame = self._frames.get(key)
            if frame is None:
                self.misses += 1
                return None
            self._frames.move_to_end(key)
            self.hits += 1
            return frame

    def put(self, key: tuple, frame: np.ndarray) -> None:
        if frame.nbytes > self.max_bytes:
            return
        with self._lock:
            old = self._frames.pop(key, None)
            self._bytes += frame.nbytes - (old.nbytes if old is not None else 0)
            self._frames[key] = frame
            while self._bytes > self.max_bytes:
                self._bytes -= self._frames.popitem(last=False)[1].nbytes

    def clear(self) -> None:
        with self._lock:
            self._frames.clear()
            self._bytes = 0
            self.hits = self.misses = 0

    def __len__(self) -> int:
        return len(self._frames)


LRU = FrameLRU(int(float(os.environ.get("RALLY3D_FRAME_LRU_MB", 64)) * 2**20))
"""The process's decoded-frame LRU; ``RALLY3D_FRAME_LRU_MB`` sets its size (default 64 MB, 0 = off)."""


def _npy_header(length: int) -> bytes:
    """The ``.npy`` header of a 1-D uint8 array of ``length`` bytes: always :data:`_NPY_HEADER_BYTES` long."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "|u1", "fortran_order": False, "shape": (length,)})
    out = buf.getvalue()
    if len(out) != _NPY_HEADER_BYTES:  # numpy pads the header for growth; never expected to differ
        raise RuntimeError(f"unexpected .npy header size {len(out)}")
    return out


class StoreWriter:
    """Writes a frame store to ``path`` (the caller writes to a temporary name and renames it when the
    count is right). Frames are RGB ``uint8 (H, W, 3)`` of ``size`` = (H, W); ``codec`` ``jpeg`` (lossy,
    :data:`QUALITY`) or ``png`` (lossless)."""

    def __init__(self, path: str | Path, size: tuple[int, int], codec: str = "jpeg",
                 quality: int | None = None, subsampling: str | None = None):
        quality, subsampling = quality or QUALITY, subsampling or SUBSAMPLING
        if subsampling not in ("420", "444"):
            raise ValueError(f"subsampling must be '420' or '444', got {subsampling!r}")
        if codec not in CODECS:
            raise ValueError(f"codec must be one of {CODECS}, got {codec!r}")
        self.codec = codec
        self.path, self.size = Path(path), tuple(size)
        self.quality, self.subsampling = int(quality), subsampling
        self._fh = open(self.path, "wb")
        self._fh.write(b"\0" * (_NPY_HEADER_BYTES + _HEAD.size))  # written for real by close()
        self._offsets, self._crcs = [_HEAD.size], []

    def __len__(self) -> int:
        return len(self._crcs)

    def add(self, frame: np.ndarray) -> None:
        if frame.shape != (*self.size, 3) or frame.dtype != np.uint8:
            raise ValueError(f"frame {len(self)}: expected uint8 {(*self.size, 3)}, "
                             f"got {frame.dtype} {frame.shape}")
        data = encode_frame(frame, self.codec, self.quality, self.subsampling)
        self._fh.write(data)
        self._offsets.append(self._offsets[-1] + len(data))
        self._crcs.append(zlib.crc32(data))

    def close(self) -> None:
        """Write the index, the tail and the headers (a store of the frames added so far)."""
        if self._fh.closed:
            return
        fh = self._fh
        try:
            pos = self._offsets[-1]
            pad = (-pos) % 8
            fh.write(b"\0" * pad)
            index = pos + pad
            fh.write(np.asarray(self._offsets, "<i8").tobytes())
            fh.write(np.asarray(self._crcs, "<u4").tobytes())
            fh.write(_TAIL.pack(index, MAGIC))
            body = fh.tell() - _NPY_HEADER_BYTES
            fh.seek(0)
            fh.write(_npy_header(body))
            fh.write(_HEAD.pack(MAGIC, VERSION, CODECS.index(self.codec), self.quality,
                                int(self.subsampling == "444"), len(self), *self.size))
            fh.flush()
            os.fsync(fh.fileno())
        finally:
            fh.close()

    def abort(self) -> None:
        self._fh.close()

    def __enter__(self) -> StoreWriter:
        return self

    def __exit__(self, exc_type, *exc) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()


class FrameStore:
    """Read access to a frame store: an array-like of ``(T, H, W, 3) uint8`` decoded on demand.

    ``store[i]`` is frame ``i`` (H, W, 3), ``store[a:b]`` (or a list of indices) a ``(k, H, W, 3)`` array;
    ``len(store)``, ``shape``, ``dtype`` and ``ndim`` as for an array. Frames come from the per-process
    :data:`LRU` when decoded recently. The object pickles without its mapping (DataLoader workers reopen
    the file), so sending it to a worker process copies nothing but the path.

    Raises:
        StoreError: at opening, when the file is not a complete store.
        FormatError: when a frame's bytes no longer match their checksum (the file was damaged on disk).
    """

    dtype = np.dtype(np.uint8)
    ndim = 4

    def __init__(self, path: str | Path):
        self.path = Path(path)
        self._open()

    def _open(self) -> None:
        try:
            body = np.load(self.path, mmap_mode="r", allow_pickle=False)
        except (ValueError, OSError, EOFError) as e:
            raise StoreError(f"not a readable .npy file ({e})") from None
        if body.dtype != np.uint8 or body.ndim != 1:
            raise StoreError(f"an array of {body.dtype} {body.shape}, not a frame store "
                             "(an older cache format?)")
        if len(body) < _HEAD.size + _TAIL.size:
            raise StoreError(f"too short for a frame store ({len(body)} bytes)")
        magic, version, codec, quality, sub, n, h, w = _HEAD.unpack(bytes(body[:_HEAD.size]))
        index, magic2 = _TAIL.unpack(bytes(body[-_TAIL.size:]))
        if magic != MAGIC or magic2 != MAGIC:
            raise StoreError("no frame-store marker at its start or end (incomplete or not a frame store)")
        if version != VERSION or codec >= len(CODECS):
            raise StoreError(f"frame-store format {version} (codec {codec}), this version reads {VERSION}")
        if index + 12 * n + 8 + _TAIL.size != len(body):
            raise StoreError(f"its index does not match its length ({len(body)} bytes for {n} frames)")
        offsets = body[index:index + 8 * (n + 1)].view("<i8")
        crcs = body[index + 8 * (n + 1):index + 12 * n + 8].view("<u4")
        if offsets[0] != _HEAD.size or not 0 <= index - offsets[-1] < 8 \
                or (n and (np.diff(offsets) <= 0).any()):
            raise StoreError("its frame offsets are inconsistent")
        self._body, self._offsets, self._crcs = body, np.array(offsets, np.int64), np.array(crcs, np.uint32)
        self.codec, self.quality, self.subsampling = CODECS[codec], int(quality), "444" if sub else "420"
        self.shape = (int(n), int(h), int(w), 3)
        st = os.stat(self.path)
        self._key = (str(self.path.resolve()), st.st_ino, st.st_mtime_ns)  # a rebuilt file is another store

    def __getstate__(self) -> dict:
        return {"path": self.path}

    def __setstate__(self, state: dict) -> None:
        self.path = state["path"]
        self._open()

    def __len__(self) -> int:
        return self.shape[0]

    @property
    def file_bytes(self) -> int:
        """The size of the file (the encoded frames and the index)."""
        return _NPY_HEADER_BYTES + len(self._body)

    def frame(self, index: int) -> np.ndarray:
        """Frame ``index`` (negative counts from the end), RGB ``uint8 (H, W, 3)``, read-only."""
        n = len(self)
        i = int(index) + (n if index < 0 else 0)
        if not 0 <= i < n:
            raise IndexError(f"frame {index} out of range: the store has {n} frames ({self.path})")
        key = (self._key, i)
        cached = LRU.get(key)
        if cached is not None:
            return cached
        frame = self._decode(i)
        frame.flags.writeable = False
        LRU.put(key, frame)
        return frame

    def _decode(self, i: int) -> np.ndarray:
        buf = self._body[self._offsets[i]:self._offsets[i + 1]]
        if zlib.crc32(buf) != int(self._crcs[i]):
            raise FormatError(self.path, f"frame {i} is damaged (its bytes no longer match their checksum)",
                              fix="delete this file: the next run rebuilds it from the video")
        frame = decode_frame(buf)
        if frame is None or frame.shape != self.shape[1:]:
            raise FormatError(self.path, f"frame {i} cannot be decoded as a {self.shape[1:]} {self.codec}",
                              fix="delete this file: the next run rebuilds it from the video")
        return frame

    def __getitem__(self, key) -> np.ndarray:
        if isinstance(key, int | np.integer):
            return self.frame(int(key))
        if isinstance(key, slice):
            idx = range(*key.indices(len(self)))
        else:
            idx = np.asarray(key)
            if idx.dtype == bool:
                idx = np.flatnonzero(idx)
            if idx.ndim != 1 or not np.issubdtype(idx.dtype, np.integer):
                raise TypeError("frame store indices must be integers, slices or 1-D integer arrays, "
                                f"got {key!r}")
        out = np.empty((len(idx), *self.shape[1:]), np.uint8)
        if len(idx) > 1:  # a window's frames decode side by side (OpenCV's decoders release the GIL)
            for k, frame in enumerate(_decoder_pool().map(self.frame, [int(i) for i in idx])):
                out[k] = frame
        else:
            for k, i in enumerate(idx):
                out[k] = self.frame(int(i))
        return out

    def __iter__(self):
        for i in range(len(self)):
            yield self.frame(i)

    def __array__(self, dtype=None, copy=None):
        out = self[:]
        return out if dtype is None else out.astype(dtype)

    def __repr__(self) -> str:
        return (f"FrameStore({str(self.path)!r}, {len(self)} frames {self.shape[1]}×{self.shape[2]}, "
                f"{self.codec}{f' q{self.quality} {self.subsampling}' if self.codec == 'jpeg' else ''}, "
                f"{self.file_bytes / 1e6:.1f} MB)")


_POOL: dict[int, ThreadPoolExecutor] = {}


def _decoder_pool() -> ThreadPoolExecutor:
    """This process's decoding threads (:data:`DECODE_THREADS`; made after a fork, never inherited)."""
    pid = os.getpid()
    if pid not in _POOL:
        _POOL.clear()
        _POOL[pid] = ThreadPoolExecutor(DECODE_THREADS, thread_name_prefix="frame-store")
    return _POOL[pid]


def write_store(path: str | Path, frames: Iterable[np.ndarray], size: tuple[int, int], codec: str = "jpeg",
                quality: int | None = None, subsampling: str | None = None) -> int:
    """Write ``frames`` to a store at ``path`` (no temporary name: see :class:`StoreWriter`); the count."""
    with StoreWriter(path, size, codec, quality, subsampling) as w:
        for frame in frames:
            w.add(frame)
    return len(w)
