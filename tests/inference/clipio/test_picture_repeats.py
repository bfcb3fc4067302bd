"""A 25 fps broadcast converted to a 30 fps file repeats every 6th picture (the timestamps stay regular):
``rally3d infer`` reads it at 25 fps with the repeats left out, so that the ball's flight has even time
steps. Every picture carries its number (binary bars), so content is checked through decoding, and a ball
moves across it (the frame differences that reveal the repeats)."""
from __future__ import annotations

import numpy as np
import pytest

from inference.clipio import Clip, FrameSource, write_video
from inference.clipio.probe import PictureRepeats, find_picture_repeats, repeat_pattern
from inference.pipeline.prepare import Cut, prepare

from test_video_nominal_rate import number_of, numbered  # noqa: E402 - the numbered frames of that test

PICTURES = 100  # 4 s at 25 fps


def picture(k: int) -> np.ndarray:
    """Picture ``k`` of the 25 fps content: its number, and a ball crossing the lower half."""
    img = numbered(k)
    x = int(20 + 2.8 * k)
    img[120:136, x:x + 16] = 255
    return img


def converted(phase: int = 3) -> list[np.ndarray]:
    """The content at 30 fps: every 6th frame (from ``phase``) repeats the picture before it."""
    frames, k = [], 0
    while k < PICTURES:
        if len(frames) >= phase and (len(frames) - phase) % 6 == 0:
            frames.append(frames[-1])
        else:
            frames.append(picture(k))
            k += 1
    return frames


def test_a_converted_broadcast_is_read_at_its_content_rate(tmp_path):
    video = tmp_path / "broadcast.mp4"
    write_video(video, converted(), 30.0)
    found = find_picture_repeats(video)
    assert found is not None and (found.period, found.phase) == (6, 3) and found.content_fps == pytest.approx(25)
    clip = prepare(video, tmp_path / "clip", "padel").clip
    assert clip.info.fps == pytest.approx(25.0) and clip.info.n_frames == PICTURES
    assert clip.info.extra["timing"]["repeated_pictures"]["period"] == 6
    with Clip(clip.root).frames() as src:
        assert len(src) == PICTURES and src.fps == pytest.approx(25.0)
        assert [number_of(f) for f in src.iter()] == list(range(PICTURES))  # no picture twice, none lost
    with FrameSource.open(clip.root) as src:  # the clip folder as a frame source reads the same
        assert number_of(src.read(50)) == 50


def test_a_cut_of_a_converted_broadcast_keeps_only_new_pictures(tmp_path):
    video = tmp_path / "broadcast.mp4"
    write_video(video, converted(phase=2), 30.0)
    clip = prepare(video, tmp_path / "cut", "padel", cut=Cut(1.0, 2.0)).clip  # 25 pictures from picture 25
    assert clip.info.fps == pytest.approx(25.0) and clip.info.n_frames == 25
    with clip.frames() as src:
        assert [number_of(f) for f in src.iter()] == list(range(25, 50))


def test_no_beat_no_repeats(tmp_path):
    """A file without repeats, a still picture and a few random repeats are read as they are."""
    video = tmp_path / "plain.mp4"
    write_video(video, [picture(k) for k in range(60)], 30.0)
    assert find_picture_repeats(video) is None
    assert prepare(video, tmp_path / "c", "padel").clip.info.fps == pytest.approx(30.0)
    assert repeat_pattern(np.zeros(100), 30.0) is None
    rng = np.random.default_rng(0)
    d = rng.uniform(1, 2, 200)
    d[[5, 40, 41, 90, 150]] = 0.0
    assert repeat_pattern(d, 30.0) is None
    d = rng.uniform(1, 2, 200)
    d[np.arange(3, 200, 7) - 1] = 0.0  # every 7th: 30 × 6/7 = 25.7 fps is no standard rate
    assert repeat_pattern(d, 30.0) is None


def test_repeats_record_round_trips():
    r = PictureRepeats(6, 3, 30.0)
    assert PictureRepeats.from_record(r.record()) == r
    assert r.keep(13).tolist() == [0, 1, 2, 4, 5, 6, 7, 8, 10, 11, 12]
    assert PictureRepeats.from_record({"period": "x"}) is None
