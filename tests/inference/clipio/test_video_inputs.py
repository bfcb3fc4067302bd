"""Real-footage video files, written in the test: .mov / .mkv containers, 50 and 60 fps, variable frame rate
(irregular timestamps), interlaced 1080i, unreadable files. Every frame carries its own number (binary bars),
so the tests check that frame i of the reader is the frame the file holds at time i / fps."""
from __future__ import annotations

import fractions

import av
import cv2
import numpy as np
import pytest

from inference.clipio import Clip, FormatError, FrameSource, write_video
from inference.clipio.probe import COMB_THRESHOLD, comb_score, probe_video_file
from inference.pipeline.prepare import Cut, prepare, video_notes

BITS = 8


def numbered(index: int, w: int = 320, h: int = 192, bits: int = BITS) -> np.ndarray:
    """A frame whose top half shows ``index`` in binary as white bars (robust to compression)."""
    img = np.full((h, w, 3), 30, np.uint8)
    bar = w // bits
    for bit in range(bits):
        if index >> bit & 1:
            img[: h // 2, bit * bar:(bit + 1) * bar] = 235
    img[h // 2:, :, 0] = 180  # red bottom half: RGB order
    return img


def number_of(img: np.ndarray, bits: int = BITS) -> int:
    h, w = img.shape[:2]
    bar = w // bits
    return sum(1 << b for b in range(bits) if img[4:h // 2 - 4, b * bar + 4:(b + 1) * bar - 4].mean() > 127)


def write_pyav(path, frames, *, fmt, codec="libx264", rate=30, pts_ms=None, options=None) -> None:
    """Encode RGB frames with PyAV; ``pts_ms``: explicit presentation times (variable frame rate)."""
    with av.open(str(path), "w", format=fmt) as c:
        s = c.add_stream(codec, rate=rate)
        s.width, s.height = frames[0].shape[1], frames[0].shape[0]
        s.pix_fmt = "yuv420p"
        s.options = {"preset": "ultrafast", **(options or {})} if codec == "libx264" else (options or {})
        if pts_ms is not None:
            s.codec_context.time_base = s.time_base = fractions.Fraction(1, 1000)
        for i, f in enumerate(frames):
            vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(f), format="rgb24")
            if pts_ms is not None:
                vf.pts, vf.time_base = pts_ms[i], fractions.Fraction(1, 1000)
            for p in s.encode(vf):
                c.mux(p)
        for p in s.encode():
            c.mux(p)


# ------------------------------------------------------------------------------------ containers and rates
@pytest.mark.parametrize("name, fps, writer", [
    ("clip.mov", 60.0, "h264"), ("clip.mkv", 50.0, "h264"), ("clip.mov", 50.0, "mp4v"), ("clip.mkv", 60.0, "MJPG"),
])
def test_containers_and_rates(tmp_path, name, fps, writer):
    n = 45
    write_video(tmp_path / name, (numbered(i) for i in range(n)), fps, fourcc=writer)
    with FrameSource.open(tmp_path / name) as src:
        assert (src.width, src.height, len(src)) == (320, 192, n)
        assert src.fps == pytest.approx(fps, rel=1e-3)
        assert src.notes == []  # constant rate, progressive: nothing to say
        assert [number_of(f) for f in src.iter()] == list(range(n))
        for i in (37, 5, 44, 0, 20):  # random access, backwards too
            assert number_of(src.read(i)) == i
        assert src.read(3)[150, 10, 0] > 150  # RGB order kept
    p = probe_video_file(tmp_path / name)
    assert p is not None and not p.vfr and not p.interlaced and p.n_frames == n


def test_infer_prepares_a_60fps_mov_and_cuts_it_in_seconds(tmp_path):
    video = tmp_path / "match.mov"
    write_video(video, (numbered(i) for i in range(120)), 60.0, fourcc="h264")
    whole = prepare(video, tmp_path / "whole", "padel").clip
    assert (whole.info.fps, whole.n_frames, whole.info.width) == (60.0, 120, 320)
    assert number_of(whole.frames()[119]) == 119
    cut = prepare(video, tmp_path / "cut", "padel", cut=Cut(0.5, 1.25)).clip  # frames 30 … 74
    with cut.frames() as src:
        assert [number_of(f) for f in src.iter()] == list(range(30, 75))
    assert cut.info.extra["cut"]["first_frame"] == 30 and cut.info.fps == 60.0


# ---------------------------------------------------------------------------------- variable frame rate
def test_variable_frame_rate_is_resampled_to_a_constant_rate(tmp_path):
    # a phone's 30 fps with stalls and bursts: gaps of 100 and 67 ms, then 10 ms steps
    pts = [0, 33, 67, 167, 200, 233, 300, 310, 320, 330, 367, 400, 433, 467, 500]
    path = tmp_path / "phone.mkv"
    write_pyav(path, [numbered(i) for i in range(len(pts))], fmt="matroska", rate=30, pts_ms=pts)
    with FrameSource.open(path) as src:
        assert src.fps == pytest.approx(30.0)
        assert len(src) == 16  # 0 … 500 ms at 30 fps
        got = [number_of(f) for f in src.iter()]
        t = np.array(pts) / 1000.0
        want = [int(np.argmin(np.abs(t - k / 30.0) + 1e-9 * np.arange(len(t)))) for k in range(16)]
        assert got == want
        assert got[2:6] == [2, 2, 3, 3]  # the 100 ms stall repeats frames
        assert 8 not in got  # the 10 ms burst drops one
        assert [number_of(src.read(k)) for k in (15, 4, 9, 0)] == [want[15], want[4], want[9], want[0]]
        assert any("variable frame rate" in n and "resampled to a constant 30 fps" in n for n in src.notes)
    clip = prepare(path, tmp_path / "out", "padel").clip
    assert clip.n_frames == 16 and clip.info.fps == pytest.approx(30.0)
    assert any("resampled" in n for n in video_notes(path))  # what `rally3d infer` prints


# ---------------------------------------------------------------------------------------- interlaced
def combed_frames(n: int, w: int = 1920, h: int = 1080) -> list[np.ndarray]:
    """1080i: each frame's even lines show a white square at time t, the odd lines at t + half a frame."""
    frames = []
    for i in range(n):
        img = np.full((h, w, 3), 60, np.uint8)
        for field, dt in ((0, 0.0), (1, 0.5)):
            x = int(300 + 120 * (i + dt))
            lines = img[field::2]
            lines[200 // 2:400 // 2, x:x + 100] = 240
        frames.append(img)
    return frames


def test_interlaced_1080i_is_detected_and_deinterlaced(tmp_path):
    frames = combed_frames(6)
    assert comb_score(frames[2]) > COMB_THRESHOLD  # the raw frames do comb
    path = tmp_path / "broadcast_1080i.mp4"
    write_pyav(path, frames, fmt="mp4", rate=25, options={"flags": "+ildct+ilme", "x264-params": "tff=1"})
    assert probe_video_file(path).field_order == "tt"
    with FrameSource.open(path) as src:
        assert any("interlaced" in n and "deinterlaced" in n for n in src.notes)
        for i, f in enumerate(src.iter()):
            assert comb_score(f) < 1.5, i
            # the square stands where the first (top) field shows it: x 300 + 120 i … + 100
            cols = np.flatnonzero(f[300, :, 0] > 150)
            assert abs(cols.min() - (300 + 120 * i)) <= 2 and abs(cols.max() - (399 + 120 * i)) <= 2


def test_unflagged_combing_is_caught_from_the_first_frame(tmp_path):
    path = tmp_path / "flagless.avi"
    write_video(path, combed_frames(4, 640, 360), 25.0, fourcc="MJPG")
    with FrameSource.open(path) as src:
        assert any("interlaced" in n for n in src.notes)
        assert comb_score(src.read(1)) < 1.5


# ----------------------------------------------------------------------------------------- bad files
@pytest.mark.parametrize("name, content", [
    ("notes.mov", b"this is a text file, not a video\n" * 20),
    ("empty.mkv", b""),
    ("half.mp4", None),  # the first 2 kB of a real video: no frame decodes
])
def test_unreadable_files_say_which_and_how_to_fix(tmp_path, name, content):
    path = tmp_path / name
    if content is None:
        write_video(tmp_path / "full.mp4", (numbered(i) for i in range(10)), 30.0, fourcc="h264")
        content = (tmp_path / "full.mp4").read_bytes()[:2000]
    path.write_bytes(content)
    with pytest.raises(FormatError) as e:
        FrameSource.open(path)
    assert str(path) in str(e.value) and "fix: re-encode" in str(e.value)
    with pytest.raises(FormatError, match=name):
        prepare(path, tmp_path / "out", "padel")
