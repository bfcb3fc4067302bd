"""Lazy frame access for a clip: a video file or a ``frames/`` folder of ``000000.jpg`` ...

Nothing loads a whole video: :meth:`FrameSource.read` decodes one frame (seeking only when the frame
is not the next one, with a small LRU cache), and :meth:`FrameSource.iter` decodes sequentially.
Frames are RGB ``uint8 (H, W, 3)``.

Example::

    with FrameSource.open("clips/rally_001") as src:
        first = src[0]
        for frame in src.iter(start=100, stop=200):
            ...
"""

from __future__ import annotations

import os
import re
from abc import ABC, abstractmethod
from collections import OrderedDict
from collections.abc import Iterable, Iterator
from pathlib import Path

import logging

import cv2
import numpy as np

from .errors import FormatError
from .probe import COMB_THRESHOLD, PictureRepeats, Resampling, comb_score, deinterlace, probe_video_file

log = logging.getLogger(__name__)

FRAME_NAME = re.compile(r"^(\d+)\.(jpg|jpeg|png)$", re.IGNORECASE)
VIDEO_FIX = (
    "re-encode the video (e.g. ffmpeg -i in.mp4 -c:v libx264 -pix_fmt yuv420p video.mp4) or extract frames/"
)
MAX_GRAB_AHEAD = 32
"""Decode forward instead of seeking when the wanted frame is at most this far ahead."""


class FrameSource(ABC):
    """Random and sequential access to the frames of one clip. Use :meth:`open`.

    Attributes:
        path: the video file or frames folder.
        fps: frames per second (None for a frames folder opened without one).
        width, height: image size in pixels.
    """

    path: Path
    fps: float | None
    width: int
    height: int

    def __init__(self, cache_size: int = 8):
        self._cache: OrderedDict[int, np.ndarray] = OrderedDict()
        self._cache_size = cache_size

    @staticmethod
    def open(path: str | Path, *, fps: float | None = None, cache_size: int = 8,
             repeats: PictureRepeats | None = None) -> FrameSource:
        """Open a clip folder (its ``clip.yaml`` names the frames), a video file, or a frames folder.

        Args:
            path: clip folder, video file or frames folder.
            fps: overrides the frame rate (a clip folder's ``clip.yaml`` gives it otherwise).
            cache_size: number of recently read frames kept in memory.
            repeats: a video whose every n-th frame repeats a picture: read without the repeats (a clip
                folder's ``clip.yaml`` says so in ``timing.repeated_pictures``).
        """
        path = Path(path)
        if path.is_dir() and (path / "clip.yaml").is_file():
            from .clip_yaml import read_clip_yaml

            info = read_clip_yaml(path / "clip.yaml")
            return FrameSource.open(path / info.video, fps=fps or info.fps, cache_size=cache_size,
                                    repeats=repeats or clip_repeats(info))
        if path.is_dir():
            return FolderFrames(path, fps=fps, cache_size=cache_size)
        if not path.exists():
            raise FormatError(
                path,
                "video file not found",
                fix="check the path, or clip.yaml's 'video' key (a file like video.mp4 or frames/)",
            )
        return VideoFrames(path, fps=fps, cache_size=cache_size, repeats=repeats)

    # --------------------------------------------------------------------------------------- access
    @abstractmethod
    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> np.ndarray:
        return self.read(index)

    def __iter__(self) -> Iterator[np.ndarray]:
        return self.iter()

    def __enter__(self) -> FrameSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Release the decoder (the source reopens it if used again)."""
        self._cache.clear()

    def read(self, index: int) -> np.ndarray:
        """Frame ``index`` (negative counts from the end) as RGB ``uint8 (H, W, 3)``.

        The array is cached and read-only: copy it before drawing on it.
        """
        index = self._check_index(index)
        frame = self._cache.get(index)
        if frame is None:
            return self._remember(index, self._decode(index))
        self._cache.move_to_end(index)
        return frame

    def _remember(self, index: int, frame: np.ndarray) -> np.ndarray:
        frame.flags.writeable = False
        self._cache[index] = frame
        if len(self._cache) > self._cache_size:
            self._cache.popitem(last=False)
        return frame

    def iter(self, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        """Frames ``start .. stop-1`` in order, decoded sequentially (``stop`` None = to the end)."""
        n = len(self)
        stop = n if stop is None else min(stop, n)
        if start < 0 or start > n:
            raise IndexError(f"start {start} is outside 0..{n}")
        return self._iter(start, stop) if start < stop else iter(())

    def _check_index(self, index: int) -> int:
        n = len(self)
        if not isinstance(index, int | np.integer):
            raise TypeError(f"frame index must be an integer, got {type(index).__name__}")
        i = int(index) + (n if index < 0 else 0)
        if not 0 <= i < n:
            raise IndexError(f"frame {index} out of range: valid frames are 0..{n - 1} (or -{n}..-1)")
        return i

    def seek_free(self, index: int) -> bool:
        """Whether reading frame ``index`` now needs no seek (it is cached, or the decoder reaches it by
        decoding forward a few frames). A caller with several frames to read can read these first, and the
        rest in ascending order, instead of seeking back and forth (a backward seek in H.264 decodes from
        the previous key frame)."""
        return True

    @abstractmethod
    def _decode(self, index: int) -> np.ndarray:
        """Decode frame ``index`` (already range-checked)."""

    @abstractmethod
    def _iter(self, start: int, stop: int) -> Iterator[np.ndarray]:
        """Decode frames ``start .. stop-1`` sequentially."""


def clip_repeats(info) -> PictureRepeats | None:
    """The repeated pictures that a clip's ``clip.yaml`` (:class:`~.clip_yaml.ClipInfo`) records in
    ``timing.repeated_pictures`` (None when it records none)."""
    timing = info.extra.get("timing") if isinstance(info.extra, dict) else None
    rec = timing.get("repeated_pictures") if isinstance(timing, dict) else None
    return PictureRepeats.from_record(rec) if rec else None


# -------------------------------------------------------------------------------------------- video
class VideoFrames(FrameSource):
    """Frames of a video file, decoded with OpenCV, presented at one constant rate and progressive.

    The container is probed first (:mod:`.probe`, PyAV): its frame count and timestamps are taken from the
    packets, a variable frame rate is resampled to the nominal rate (nearest timestamp; ``resampling`` says
    which frames were repeated and dropped) and interlaced video is deinterlaced. ``notes`` says what was
    done (also logged, level INFO).
    """

    def __init__(self, path: str | Path, *, fps: float | None = None, cache_size: int = 8,
                 repeats: PictureRepeats | None = None):
        super().__init__(cache_size)
        self.path = Path(path)
        self._cap: cv2.VideoCapture | None = None
        self._next = 0  # the source frame the open capture will return next
        self.notes: list[str] = []
        self.probe = probe_video_file(self.path)
        # OpenCV's FFmpeg backend returns blank frames for interlaced H.264 ("cannot convert interlaced to
        # progressive"): such files are decoded with PyAV
        self._pyav = self.probe is not None and self.probe.interlaced
        cap = self._capture()
        self.fps = fps or (self.probe.fps if self.probe else None) or (cap.get(cv2.CAP_PROP_FPS) or None)
        self._n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))  # OpenCV's duration × rate: right at a constant rate
        if self._pyav:
            self._n = self.probe.n_frames
        self._map: np.ndarray | None = None  # constant-rate frame → source frame (variable frame rate only)
        self.resampling: Resampling | None = None
        if self.probe is not None and self.probe.vfr and self.fps:
            self._n = self.probe.n_frames  # the packets, not OpenCV's estimate
            self.resampling = self.probe.resampling(self.fps)
            self._map = self.resampling.source
            self.notes.append(self.resampling.note())
        elif repeats is not None:  # a lower-rate content in a higher-rate file: the repeated pictures left out
            self.fps = fps or repeats.content_fps
            self._map = repeats.keep(self.probe.n_frames if self.probe is not None else self._n)
            self.notes.append(repeats.note(self.path.name))
        first = self._read_next(0)
        if self._n <= 0:
            self._n = self._count_frames()
        self._field = self.probe.field_order if self.probe is not None and self.probe.interlaced else None
        if self._field is None and (self.probe is None or self.probe.field_order == "unknown") \
                and comb_score(first) > COMB_THRESHOLD:
            self._field = "tt"  # unflagged, but the first frame is combed
        if self._field is not None:
            self.notes.append(f"{self.path.name}: interlaced video (field order {self._field}): deinterlaced "
                              "(first field kept, the other interpolated; half the vertical detail)")
        for note in self.notes:  # `rally3d infer` prints them once (prepare.video_notes); readers open often
            log.info(note)
        first = self._remember(0, self._progressive(first))
        self.height, self.width = first.shape[:2]

    def __len__(self) -> int:
        return self._n if self._map is None else len(self._map)

    def _progressive(self, frame: np.ndarray) -> np.ndarray:
        return frame if self._field is None else deinterlace(frame, self._field)

    def close(self) -> None:
        super().close()
        self._release()

    def _release(self) -> None:
        if self._cap is not None:
            self._cap.release()
            self._cap = None

    def _open(self) -> cv2.VideoCapture:
        cap = _PyAVCapture(self.path) if self._pyav else cv2.VideoCapture(str(self.path))
        if not cap.isOpened():
            raise FormatError(
                self.path, "cannot open the video (corrupt or unsupported format)", fix=VIDEO_FIX
            )
        return cap

    def _capture(self) -> cv2.VideoCapture:
        if self._cap is None:
            self._cap = self._open()
            self._next = 0
        return self._cap

    def _decode_error(self, index: int) -> FormatError:
        self._release()
        problem = f"cannot decode frame {index} (the video reports {self._n} frames)"
        return FormatError(self.path, problem, fix=VIDEO_FIX)

    def _read_next(self, index: int) -> np.ndarray:
        ok, bgr = self._capture().read()
        if not ok or bgr is None:
            raise self._decode_error(index)
        self._next = index + 1
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)

    def seek_free(self, index: int) -> bool:
        if not 0 <= index < len(self):
            return False
        if index in self._cache:
            return True
        source = index if self._map is None else int(self._map[index])
        return self._cap is not None and self._next <= source <= self._next + MAX_GRAB_AHEAD

    def _decode(self, index: int) -> np.ndarray:
        source = index if self._map is None else int(self._map[index])
        return self._progressive(self._decode_source(source))

    def _decode_source(self, index: int) -> np.ndarray:
        """Source frame ``index`` (decode order of presentation), as decoded."""
        cap = self._capture()
        if not self._next <= index <= self._next + MAX_GRAB_AHEAD:
            cap = self._cap = self._seek(cap, index)
            self._next = index
        while self._next < index:  # a few frames ahead: decoding forward is cheaper than seeking
            if not cap.grab():
                raise self._decode_error(index)
            self._next += 1
        return self._read_next(index)

    def _seek(self, cap: cv2.VideoCapture, index: int) -> cv2.VideoCapture:
        """Position ``cap`` at ``index``; if its seek is inexact (always assumed with irregular timestamps,
        where OpenCV seeks by time), decode forward from a fresh capture."""
        if self._map is None:
            cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            if int(cap.get(cv2.CAP_PROP_POS_FRAMES)) == index:
                return cap
        cap.release()
        cap = self._open()
        for _ in range(index):
            if not cap.grab():
                raise self._decode_error(index)
        return cap

    def _count_frames(self) -> int:
        cap, n = self._open(), 0
        while cap.grab():
            n += 1
        cap.release()
        return n

    def _iter(self, start: int, stop: int) -> Iterator[np.ndarray]:
        if self._map is None:
            for frame in self._iter_source(start, stop):
                yield self._progressive(frame)
            return
        wanted = self._map[start:stop]
        source = self._iter_source(int(wanted[0]), int(wanted[-1]) + 1)
        at, frame = int(wanted[0]) - 1, None
        for j in wanted:  # repeated source frames are yielded again, skipped ones decoded and dropped
            while at < j:
                frame, at = next(source), at + 1
            yield self._progressive(frame)

    def _iter_source(self, start: int, stop: int) -> Iterator[np.ndarray]:
        cap = self._open()  # its own decoder, so random access during the loop does not disturb it
        try:
            if start:
                cap = self._seek(cap, start)
            for index in range(start, stop):
                ok, bgr = cap.read()
                if not ok:
                    raise FormatError(
                        self.path,
                        f"the video ends at frame {index} but reports {self._n} frames",
                        fix=VIDEO_FIX,
                    )
                yield cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        finally:
            cap.release()


class _PyAVCapture:
    """The part of ``cv2.VideoCapture``'s interface :class:`VideoFrames` uses, decoding with PyAV (sequential
    only: it cannot seek, so the reader decodes forward)."""

    def __init__(self, path: Path):
        import av

        self._av = av
        try:
            self._container = av.open(str(path))
            self._stream = self._container.streams.video[0]
            self._stream.thread_type = "AUTO"
            self._frames = self._container.decode(self._stream)
        except (av.FFmpegError, IndexError, OSError):
            self._container = None

    def isOpened(self) -> bool:  # noqa: N802 - OpenCV's name
        return self._container is not None

    def _next(self):
        try:
            return next(self._frames)
        except (StopIteration, self._av.FFmpegError):
            return None

    def grab(self) -> bool:
        return self._next() is not None

    def read(self) -> tuple[bool, np.ndarray | None]:
        frame = self._next()
        return (False, None) if frame is None else (True, frame.to_ndarray(format="bgr24"))

    def get(self, prop: int) -> float:
        if prop == cv2.CAP_PROP_FPS:
            return float(self._stream.average_rate or 0)
        if prop == cv2.CAP_PROP_FRAME_COUNT:
            return float(self._stream.frames or 0)
        return -1.0  # position unknown: seeking is never trusted

    def set(self, prop: int, value: float) -> bool:
        return False

    def release(self) -> None:
        if self._container is not None:
            self._container.close()
            self._container = None


# ------------------------------------------------------------------------------------ frames folder
class FolderFrames(FrameSource):
    """Frames stored as images ``000000.jpg, 000001.jpg, ...`` (zero-based, no gaps)."""

    def __init__(self, path: str | Path, *, fps: float | None = None, cache_size: int = 8,
                 repeats: PictureRepeats | None = None):
        super().__init__(cache_size)
        self.path = Path(path)
        self.fps = fps
        self._files = _frame_files(self.path)
        first = self._remember(0, self._decode(0))
        self.height, self.width = first.shape[:2]

    def __len__(self) -> int:
        return len(self._files)

    def _decode(self, index: int) -> np.ndarray:
        file = self._files[index]
        bgr = cv2.imread(str(file), cv2.IMREAD_COLOR)
        if bgr is None:
            raise FormatError(
                file, "cannot decode the image", fix="replace the file with a valid JPEG or PNG"
            )
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)

    def _iter(self, start: int, stop: int) -> Iterator[np.ndarray]:
        for index in range(start, stop):
            yield self._decode(index)


def _frame_files(folder: Path) -> list[Path]:
    numbered = sorted(
        (int(m.group(1)), folder / name) for name in os.listdir(folder) if (m := FRAME_NAME.match(name))
    )
    if not numbered:
        raise FormatError(
            folder, "no frame images found", fix="name frames 000000.jpg, 000001.jpg, ... (zero-based)"
        )
    for expected, (index, file) in enumerate(numbered):
        if index != expected:
            problem = (
                f"duplicate frame number {index} ({file.name})"
                if index < expected
                else f"frame {expected} is missing (next is {file.name})"
            )
            raise FormatError(folder, problem, fix="frames must be numbered 0, 1, 2, ... without gaps")
    return [file for _, file in numbered]


# ------------------------------------------------------------------------------------------ writers
def _check_frame(frame: np.ndarray, shape: tuple[int, ...] | None, index: int) -> np.ndarray:
    frame = np.asarray(frame)
    if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
        raise ValueError(f"frame {index} must be RGB uint8 (H, W, 3), got {frame.dtype} {frame.shape}")
    if shape is not None and frame.shape != shape:
        raise ValueError(f"frame {index} has shape {frame.shape}, but the first frame has {shape}")
    return frame


def write_video(
    path: str | Path, frames: Iterable[np.ndarray], fps: float, *, fourcc: str = "mp4v", crf: int = 23
) -> int:
    """Stream RGB ``uint8 (H, W, 3)`` frames into a video file.

    Args:
        fourcc: ``mp4v`` (MPEG-4 part 2, OpenCV, fast), ``MJPG``, ... or ``h264`` (libx264 through PyAV,
            ``ultrafast`` preset, since opencv-python-headless cannot encode H.264; the container follows the
            suffix: ``.mp4``, ``.mov`` or ``.mkv``).
        crf: H.264 quality (lower is better; 23 is libx264's default).

    The file appears atomically when all frames are written. Returns the number of frames.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
    sink, shape, count = None, None, 0
    try:
        for count, frame in enumerate(frames):
            frame = _check_frame(frame, shape, count)
            if sink is None:
                shape = frame.shape
                sink = _H264Sink(tmp, fps, shape, crf) if fourcc.lower() == "h264" else _CvSink(tmp, fourcc, fps, shape)
            sink.write(frame)
        if sink is None:
            raise ValueError("no frames to write")
        sink.close()
        sink = None
        os.replace(tmp, path)
    finally:
        if sink is not None:
            sink.close()
        tmp.unlink(missing_ok=True)
    return count + 1


class _CvSink:
    """OpenCV ``VideoWriter`` for RGB frames."""

    def __init__(self, path: Path, fourcc: str, fps: float, shape: tuple[int, ...]):
        self.writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*fourcc), float(fps), (shape[1], shape[0]))
        if not self.writer.isOpened():
            raise OSError(f"OpenCV cannot write {fourcc!r} video to {path}")

    def write(self, frame: np.ndarray) -> None:
        self.writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))

    def close(self) -> None:
        self.writer.release()


class _H264Sink:
    """H.264 (libx264, yuv420p) through PyAV for RGB frames."""

    def __init__(self, path: Path, fps: float, shape: tuple[int, ...], crf: int):
        import fractions

        import av

        fmt = {".mov": "mov", ".mkv": "matroska", ".webm": "matroska"}.get(path.suffix.lower(), "mp4")
        self.container = av.open(str(path), "w", format=fmt)
        rate = fractions.Fraction(fps).limit_denominator(1001)
        self.stream = self.container.add_stream("libx264", rate=rate)
        self.stream.width, self.stream.height = shape[1] - shape[1] % 2, shape[0] - shape[0] % 2
        self.stream.pix_fmt = "yuv420p"
        self.stream.options = {"preset": "ultrafast", "crf": str(crf)}
        self.av = av

    def write(self, frame: np.ndarray) -> None:
        frame = frame[: self.stream.height, : self.stream.width]
        for packet in self.stream.encode(self.av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")):
            self.container.mux(packet)

    def close(self) -> None:
        for packet in self.stream.encode():
            self.container.mux(packet)
        self.container.close()


def write_frames_folder(folder: str | Path, frames: Iterable[np.ndarray], *, quality: int = 95) -> int:
    """Write RGB frames as ``000000.jpg, 000001.jpg, ...`` into ``folder``; returns the count.

    Numbered images left over from an older, longer sequence are removed.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    shape, count = None, 0
    for count, frame in enumerate(frames):
        frame = _check_frame(frame, shape, count)
        shape = frame.shape
        bgr = cv2.cvtColor(frame, cv2.COLOR_RGB2BGR)
        if not cv2.imwrite(str(folder / f"{count:06d}.jpg"), bgr, [cv2.IMWRITE_JPEG_QUALITY, quality]):
            raise OSError(f"cannot write {folder / f'{count:06d}.jpg'}")
    written = count + 1 if shape is not None else 0
    for name in os.listdir(folder):
        m = FRAME_NAME.match(name)
        if m and (int(m.group(1)) >= written or not name.endswith(".jpg") or len(m.group(1)) != 6):
            os.unlink(folder / name)
    return written
