"""FrameSource on generated videos (mp4v via OpenCV, H.264 with B-frames via PyAV) and frames folders."""

import random

import cv2
import numpy as np
import pytest

from inference.clipio import (
    ClipInfo,
    FolderFrames,
    FormatError,
    FrameSource,
    VideoFrames,
    write_clip_yaml,
    write_frames_folder,
    write_video,
)

W, H, N, BITS = 160, 96, 60, 6
BAR = W // BITS


def frame_image(index: int) -> np.ndarray:
    """A frame whose top half encodes ``index`` in binary as black/white bars (robust to compression)."""
    img = np.zeros((H, W, 3), np.uint8)
    for bit in range(BITS):
        if index >> bit & 1:
            img[: H // 2, bit * BAR : (bit + 1) * BAR] = 255
    img[H // 2 :, :, 0] = 200  # red bottom half: checks the RGB channel order
    return img


def frame_index(img: np.ndarray) -> int:
    return sum(
        1 << b for b in range(BITS) if img[4 : H // 2 - 4, b * BAR + 4 : (b + 1) * BAR - 4].mean() > 127
    )


def write_h264(path, n):
    av = pytest.importorskip("av")
    with av.open(str(path), "w") as container:
        stream = container.add_stream("libx264", rate=25)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        stream.options = {"bf": "3", "g": "12"}
        for i in range(n):
            container.mux(stream.encode(av.VideoFrame.from_ndarray(frame_image(i), format="rgb24")))
        container.mux(stream.encode())
    return path


def make_source(kind, folder):
    frames = (frame_image(i) for i in range(N))
    if kind == "mp4v":
        assert write_video(folder / "video.mp4", frames, fps=25) == N
        return folder / "video.mp4"
    if kind == "h264":
        return write_h264(folder / "video.mp4", N)
    assert write_frames_folder(folder / "frames", frames) == N
    return folder / "frames"


@pytest.fixture(scope="module", params=["mp4v", "h264", "folder"])
def source_path(request, tmp_path_factory):
    return make_source(request.param, tmp_path_factory.mktemp(request.param))


@pytest.fixture(scope="module", params=["mp4v", "h264"])
def video_path(request, tmp_path_factory):
    return make_source(request.param, tmp_path_factory.mktemp(request.param))


def test_frame_generator_round_trip():
    assert [frame_index(frame_image(i)) for i in range(N)] == list(range(N))


def test_properties(source_path):
    with FrameSource.open(source_path) as src:
        assert len(src) == N
        assert (src.width, src.height) == (W, H)
        assert src.fps == (None if source_path.name == "frames" else pytest.approx(25.0))
        frame = src[0]
        assert frame.shape == (H, W, 3) and frame.dtype == np.uint8
        assert frame[H - 10, 10, 0] > 150 and frame[H - 10, 10, 2] < 50, "frames are RGB"


def test_random_access_in_shuffled_order(source_path):
    order = list(range(N)) * 2
    random.Random(1).shuffle(order)
    with FrameSource.open(source_path, cache_size=4) as src:
        assert [frame_index(src.read(i)) for i in order] == order
        assert frame_index(src[-1]) == N - 1


def test_sequential_iteration(source_path):
    with FrameSource.open(source_path) as src:
        assert [frame_index(f) for f in src] == list(range(N))
        assert [frame_index(f) for f in src.iter(start=17, stop=23)] == list(range(17, 23))
        assert [frame_index(f) for f in src.iter(start=N - 2, stop=N + 10)] == [N - 2, N - 1]
        assert list(src.iter(start=5, stop=5)) == []
        # random access while an iteration is under way does not disturb it
        it = src.iter(start=10)
        assert frame_index(next(it)) == 10
        assert frame_index(src[40]) == 40
        assert frame_index(next(it)) == 11


def test_inexact_seek_falls_back_to_decoding_forward(video_path, monkeypatch):
    """A decoder whose seek lands 3 frames early is detected; frames still come back exact."""

    class LyingCapture:
        def __init__(self, cap):
            self._cap = cap

        def __getattr__(self, name):
            return getattr(self._cap, name)

        def set(self, prop, value):
            if prop == cv2.CAP_PROP_POS_FRAMES:
                value = max(0, value - 3)
            return self._cap.set(prop, value)

    real_open = VideoFrames._open
    monkeypatch.setattr(VideoFrames, "_open", lambda self: LyingCapture(real_open(self)))
    with FrameSource.open(video_path, cache_size=1) as src:
        order = [50, 3, 45, 0, 59]
        assert [frame_index(src[i]) for i in order] == order
        assert [frame_index(f) for f in src.iter(start=40, stop=43)] == [40, 41, 42]


@pytest.mark.parametrize("index", [N, N + 5, -N - 1])
def test_index_out_of_range(source_path, index):
    with FrameSource.open(source_path) as src, pytest.raises(IndexError, match=f"0..{N - 1}"):
        src[index]


def test_cache_returns_read_only_frames(source_path):
    with FrameSource.open(source_path, cache_size=2) as src:
        a = src[3]
        assert src[3] is a
        with pytest.raises(ValueError):
            a[0, 0, 0] = 1


def test_open_dispatch(source_path):
    expected = FolderFrames if source_path.name == "frames" else VideoFrames
    assert isinstance(FrameSource.open(source_path), expected)


def test_open_clip_folder(tmp_path):
    write_frames_folder(tmp_path / "frames", (frame_image(i) for i in range(5)))
    write_clip_yaml(tmp_path / "clip.yaml", ClipInfo("padel", 50.0, W, H, "frames/"))
    with FrameSource.open(tmp_path) as src:
        assert len(src) == 5 and src.fps == 50.0
        assert frame_index(src[4]) == 4


def test_corrupt_video(tmp_path):
    path = tmp_path / "video.mp4"
    path.write_bytes(np.random.default_rng(0).integers(0, 256, 20_000, dtype=np.uint8).tobytes())
    with pytest.raises(FormatError, match=r"video.mp4.*fix:"):
        FrameSource.open(path)


def test_missing_video(tmp_path):
    with pytest.raises(FormatError, match=r"video.mp4: video file not found"):
        FrameSource.open(tmp_path / "video.mp4")


@pytest.mark.parametrize(
    ("names", "message"),
    [
        ([], "no frame images"),
        (["000000.jpg", "000002.jpg"], "frame 1 is missing"),
        (["000000.jpg", "0.png"], "duplicate frame number 0"),
    ],
)
def test_bad_frames_folder(tmp_path, names, message):
    (tmp_path / "frames").mkdir()
    for name in names:
        (tmp_path / "frames" / name).write_bytes(b"")
    with pytest.raises(FormatError, match=message):
        FrameSource.open(tmp_path / "frames")


def test_undecodable_frame_image(tmp_path):
    write_frames_folder(tmp_path, (frame_image(i) for i in range(3)))
    (tmp_path / "000001.jpg").write_bytes(b"not a jpeg")
    with FrameSource.open(tmp_path) as src, pytest.raises(FormatError, match=r"000001.jpg: cannot decode"):
        src[1]


def test_write_frames_folder_removes_stale_frames(tmp_path):
    assert write_frames_folder(tmp_path, (frame_image(i) for i in range(6))) == 6
    assert write_frames_folder(tmp_path, (frame_image(i) for i in range(3))) == 3
    assert sorted(p.name for p in tmp_path.iterdir()) == ["000000.jpg", "000001.jpg", "000002.jpg"]


@pytest.mark.parametrize(
    ("frames", "message"),
    [
        ([], "no frames"),
        ([np.zeros((8, 8), np.uint8)], r"\(H, W, 3\)"),
        ([np.zeros((8, 8, 3), np.uint8), np.zeros((8, 16, 3), np.uint8)], "first frame"),
    ],
)
def test_write_video_rejects_bad_frames_and_keeps_old_file(tmp_path, frames, message):
    path = tmp_path / "video.mp4"
    path.write_bytes(b"old")
    with pytest.raises(ValueError, match=message):
        write_video(path, frames, fps=25)
    assert path.read_bytes() == b"old"
    assert [p.name for p in tmp_path.iterdir()] == ["video.mp4"]


def test_write_video_h264_random_access(tmp_path):
    """H.264 written through PyAV reads back with exact random access."""
    from inference.clipio import FrameSource, write_video

    frames = [np.full((64, 96, 3), 8 * i, np.uint8) for i in range(24)]
    assert write_video(tmp_path / "v.mp4", frames, 25.0, fourcc="h264", crf=10) == 24
    src = FrameSource.open(tmp_path / "v.mp4")
    assert len(src) == 24
    for i in (17, 3, 22, 0):
        assert abs(int(src[i].mean()) - 8 * i) <= 3
