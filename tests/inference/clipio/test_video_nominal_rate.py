"""A 25 fps broadcast with dropped frames (and one stray frame) is read at its nominal 25 fps, not at the
lower average rate its container states: frames are placed by their timestamps on the 25 fps grid, the
gaps repeat the frame before, and the reader, the infer note and clip.yaml say which frames were repeated
and dropped. Every frame carries its number (binary bars), so content is checked through decoding."""
from __future__ import annotations

import fractions
import logging
import re

import av
import numpy as np
import pytest

from inference.clipio import FrameSource
from inference.clipio.probe import nominal_rate, probe_video_file, standard_rate
from inference.pipeline.prepare import Cut, prepare, video_notes

import test_video_inputs as inputs  # noqa: E402 - the numbered frames (tests/ is on the path)

BITS = 9
SLOTS = 120  # 4.8 s at 25 fps
MISSING = [5, 17, 18, 40, 41, 42, 77, 100]  # dropped by the recorder: one, two and three in a row
STRAY = 60.5  # one extra frame half-way between slots 60 and 61 (shown by no grid frame)
STRAY_NUMBER = 500


def numbered(index: int, w: int = 320, h: int = 192) -> np.ndarray:
    """A frame showing ``index`` in binary as white bars on its top half (robust to compression)."""
    return inputs.numbered(index, w, h, bits=BITS)


def number_of(img: np.ndarray) -> int:
    return inputs.number_of(img, bits=BITS)


def recorded() -> list[tuple[float, int]]:
    """(slot time in frames at 25 fps, number shown) of every recorded frame, in time order."""
    slots = [(float(k), k) for k in range(SLOTS) if k not in MISSING]
    return sorted(slots + [(STRAY, STRAY_NUMBER)])


def write_broadcast(path, fmt: str, time_base: int) -> None:
    """H.264 at a stated 25 fps whose frames carry explicit timestamps (``1 / time_base`` s ticks)."""
    tb = fractions.Fraction(1, time_base)
    with av.open(str(path), "w", format=fmt) as c:
        s = c.add_stream("libx264", rate=25)
        s.width, s.height, s.pix_fmt = 320, 192, "yuv420p"
        s.options = {"preset": "ultrafast"}
        s.codec_context.time_base = s.time_base = tb
        for t, number in recorded():
            vf = av.VideoFrame.from_ndarray(numbered(number), format="rgb24")
            vf.pts, vf.time_base = int(round(t * time_base / 25)), tb
            for p in s.encode(vf):
                c.mux(p)
        for p in s.encode():
            c.mux(p)


def expected_numbers() -> list[int]:
    """The number the reader should show at each 25 fps frame: the recorded frame nearest in time (ties to
    the earlier one)."""
    rec = recorded()
    return [min(rec, key=lambda r: (abs(r[0] - k), r[0]))[1] for k in range(SLOTS)]


@pytest.mark.parametrize("name, fmt, time_base",
                         [("broadcast.mp4", "mp4", 90000), ("broadcast.mkv", "matroska", 1000)])
def test_dropped_frames_are_read_at_the_nominal_rate(tmp_path, caplog, name, fmt, time_base):
    path = tmp_path / name
    write_broadcast(path, fmt, time_base)
    probe = probe_video_file(path)
    assert probe.n_frames == SLOTS - len(MISSING) + 1 and probe.vfr
    assert probe.nominal_fps == 25.0 and probe.fps == 25.0
    want = expected_numbers()
    repeated = [k for k in range(1, SLOTS) if want[k] == want[k - 1]]
    assert len(repeated) == len(MISSING) and repeated[:3] == [5, 17, 19]  # 18's gap: 16 shown twice, 19 early
    with caplog.at_level(logging.INFO, logger="inference.clipio.frames"), FrameSource.open(path) as src:
        assert src.fps == 25.0 and len(src) == SLOTS
        frames = list(src.iter())
        assert [number_of(f) for f in frames] == want
        for k in (0, 5, 41, 61, 119):  # the pictures, not only their numbers (lossy: a tolerance)
            assert np.abs(frames[k].astype(int) - numbered(want[k])).mean() < 6, k
        assert [number_of(src.read(k)) for k in (100, 18, 61, 3)] == [want[k] for k in (100, 18, 61, 3)]
        rs = src.resampling
        assert rs.repeated.tolist() == repeated
        stray = [i for i, (_, n) in enumerate(recorded()) if n == STRAY_NUMBER]
        assert rs.dropped.tolist() == stray and STRAY_NUMBER not in want
        note = next(n for n in src.notes if "variable frame rate" in n)
    assert "constant 25 fps" in note and f"8 repeated: frames {', '.join(map(str, repeated))}" in note
    assert f"1 dropped: source frames {stray[0]}" in note
    assert note in caplog.text  # the log line
    if fmt == "mp4":  # the container's average rate is the one dropped frames pull down
        assert probe.stated_fps == pytest.approx(25 * (len(recorded()) - 1) / (SLOTS - 1), rel=1e-3)
        assert re.search(r"container's average 23\.5\d fps is not used", note), note

    clip = prepare(path, tmp_path / "out", "padel").clip  # what `rally3d infer VIDEO` writes
    assert clip.info.fps == 25.0 and clip.n_frames == SLOTS
    timing = clip.info.extra["timing"]
    assert timing["repeated"] == 8 and timing["repeated_frames"] == repeated
    assert timing["dropped"] == 1 and timing["dropped_source_frames"] == stray
    assert timing["source_frames"] == probe.n_frames and timing["fps"] == 25.0
    assert note in video_notes(path)  # printed by `rally3d infer`

    cut = prepare(path, tmp_path / "cut", "padel", cut=Cut(1.0, 3.0)).clip  # frames 25 … 74, re-encoded
    assert cut.info.fps == 25.0 and cut.n_frames == 50
    with cut.frames() as src:
        assert [number_of(f) for f in src.iter()] == want[25:75]
    assert cut.info.extra["timing"]["repeated_frames"] == [k - 25 for k in repeated if 25 < k < 75]
    assert cut.info.extra["timing"]["dropped"] == 1


def test_rates_are_standard_only_when_close():
    assert standard_rate(2997 / 100) == pytest.approx(30000 / 1001) and standard_rate(25.0) == 25.0
    assert standard_rate(21.9) is None and standard_rate(2000.0) is None and standard_rate(None) is None
    t = np.array([0, 1, 2, 4, 5, 6, 9, 10]) / 25.0  # 25 fps with gaps
    assert nominal_rate([25.0, 21.9], t) == 25.0
    assert nominal_rate([50.0, None], t) == 25.0  # a field rate the spacing refutes: the spacing's rate
    assert nominal_rate([2000.0], np.round(t * 1000) / 1000) == 25.0  # millisecond timestamps
    assert nominal_rate([None], np.arange(8) / 21.0) is None  # regular, unusual rate: the container decides
