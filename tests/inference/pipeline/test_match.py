"""``rally3d infer`` on a whole match: the rallies found in one pass, a clip folder each, an index, resuming."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from inference.cli import main
from inference.clipio import Clip
from inference.clipio.frames import FrameSource
from inference.pipeline import match as M
from inference.pipeline.run import PipelineReport, StageReport

FPS = 30.0


def _cutaway(seed: int, n: int, size=(180, 320)) -> list[np.ndarray]:
    """A replay / close-up: a flat colour with a moving disc (nothing like the court view)."""
    rng = np.random.default_rng(seed)
    base = np.zeros((*size, 3), np.uint8)
    base[:] = rng.integers(0, 256, 3)
    out = []
    for i in range(n):
        im = base.copy()
        yy, xx = np.mgrid[:size[0], :size[1]]
        im[(yy - 90) ** 2 + (xx - 80 - 2 * i) ** 2 < 40 ** 2] = 255
        out.append(im)
    return out


@pytest.fixture(scope="module")
def match_video(tmp_path_factory) -> tuple[Path, list[tuple[str, int, int]]]:
    """A small broadcast 'match': three rallies of a rendered tennis clip with cut-aways between them and a
    2 s glimpse of the court between two cut-aways (too short to be a rally). Returns the video and its
    scenes ``(kind, first, stop)``."""
    import cv2

    from inference.clipio import write_video
    from synth.generate import SynthConfig, generate_clip

    root = tmp_path_factory.mktemp("match")
    cfg = SynthConfig(sport="tennis", randomise_camera=False, fps=FPS, width=320, height=180, codec="mp4v",
                      max_frames=150)
    generate_clip(root / "rally", seed=5, config=cfg)
    court = [cv2.resize(f, (320, 180)) for f in Clip(root / "rally").frames(cache_size=0).iter()]
    seq: list[np.ndarray] = []
    truth: list[tuple[str, int, int]] = []
    for kind, frames in (("rally", court), ("cutaway", _cutaway(1, 60)), ("rally", court[10:]),
                         ("cutaway", _cutaway(2, 30)), ("glimpse", court[:60]), ("cutaway", _cutaway(3, 45)),
                         ("rally", court)):
        truth.append((kind, len(seq), len(seq) + len(frames)))
        seq.extend(frames)
    video = root / "match.mp4"
    write_video(video, iter(seq), FPS, fourcc="h264", crf=20)
    return video, truth


def _rallies(truth):
    return [(a, b) for kind, a, b in truth if kind == "rally"]


def test_scan_and_plan_find_the_rallies_between_cutaways(match_video):
    video, truth = match_video
    scan = M.scan_video(video)
    assert scan.n_frames == truth[-1][2] and len(scan.diffs) == scan.n_frames - 1
    plan = M.plan_rallies(scan)
    got = [(r.first_frame, r.stop_frame) for r in plan]
    want = _rallies(truth)
    assert len(got) == len(want), (got, want)
    for (a, b), (ta, tb) in zip(got, want):
        assert abs(a - ta) <= 1 and abs(b - tb) <= 1, (got, want)
    assert [r.rally for r in plan] == [1, 2, 3] and plan[1].clip == "rally_002"


def test_a_long_view_is_split_at_its_quietest_moments():
    """A club camera never cuts: a 200 s view is split where the picture is quietest (between points)."""
    n = int(200 * FPS)
    rng = np.random.default_rng(0)
    diffs = (3.0 + rng.random(n - 1)).astype(np.float32)  # players and ball moving
    quiet = [(48, 52), (108, 113), (157, 161)]            # seconds: players walking back, nothing else
    for a, b in quiet:
        diffs[int(a * FPS):int(b * FPS)] = 0.2
    scan = M.Scan(diffs, np.zeros((int(n / 15) + 1, 27, 48, 3), np.float32), 15, FPS, n)
    plan = M.plan_rallies(scan, M.MatchParams(min_rally_s=4, max_rally_s=90))
    cuts = [r.first_frame / FPS for r in plan[1:]]
    assert len(plan) == 4, cuts
    for c, (a, b) in zip(cuts, quiet):
        assert a <= c <= b, (cuts, quiet)
    lengths = [r.n_frames / FPS for r in plan]
    # a pause split in two (the light changes) leaves no empty rally between its halves
    jumpy = diffs.copy()
    jumpy[int(100 * FPS):int(114 * FPS)] = 0.2   # a 14 s pause (108–113 was one) …
    jumpy[int(107 * FPS):int(107 * FPS) + 20] = 3.0  # … with a change of light in its middle (no cut)
    plan2 = M.plan_rallies(M.Scan(jumpy, scan.blocks, 15, FPS, n), M.MatchParams(min_rally_s=4, max_rally_s=90))
    assert len(plan2) == 4 and all(r.n_frames >= 40 * FPS for r in plan2), [(r.first_frame / FPS, r.n_frames / FPS)
                                                                          for r in plan2]
    assert all(4 <= s <= 90 for s in lengths) and sum(r.n_frames for r in plan) == n
    # no pause: a view over max_rally_s is cut at its quietest second, in the middle of it
    busy = (3.0 + rng.random(n - 1)).astype(np.float32)
    busy[int(70 * FPS):int(71 * FPS)] = 1.0
    plan = M.plan_rallies(M.Scan(busy, scan.blocks, 15, FPS, n), M.MatchParams(min_rally_s=4, max_rally_s=90))
    assert 69.5 <= plan[1].first_frame / FPS <= 71.5 and all(r.n_frames <= 90 * FPS for r in plan), \
        [r.first_frame / FPS for r in plan]
    # a view within the limit and without a pause stays whole
    assert M.split_view(0, int(80 * FPS), np.ones(n), FPS, M.MatchParams()) == [(0, int(80 * FPS))]
    with pytest.raises(ValueError, match="twice min_rally_s"):
        M.MatchParams(min_rally_s=50, max_rally_s=60)


def test_cli_match_writes_a_clip_per_rally_and_an_index(match_video, tmp_path, capsys):
    video, truth = match_video
    out = tmp_path / "final"
    code = main(["infer", str(video), "--match", "--court", "tennis", "--only", "scenes", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 0, err
    with open(out / M.INDEX_FILE, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["clip"] for r in rows] == ["rally_001", "rally_002", "rally_003"]
    assert all(r["status"] == "done" for r in rows)
    src = Clip(video.parent / "rally")  # what the match was made of
    for row, (a, b) in zip(rows, _rallies(truth)):
        clip = Clip(out / row["clip"])
        assert clip.info.n_frames == int(row["stop_frame"]) - int(row["first_frame"])
        assert abs(int(row["first_frame"]) - a) <= 1 and abs(float(row["start_s"]) - a / FPS) < 0.05
        assert clip.info.extra["cut"]["first_frame"] == int(row["first_frame"])
        assert (out / row["clip"] / "scenes.json").is_file()
    # the second rally's first frame is the match's frame at its start (decoded, with a tolerance)
    with Clip(out / "rally_002").frames(cache_size=0) as fr, FrameSource.open(video, cache_size=0) as whole:
        first = int(rows[1]["first_frame"])
        d = np.abs(fr.read(0).astype(float) - whole.read(first).astype(float)).mean()
    assert d < 6.0, d
    assert src.n_frames == 150
    log = (out / M.LOG_FILE).read_text()
    assert "[scan]" in log and "frames/s" in log and "ETA" in log and "3 done" in log
    assert "rally 3/3" in err and "ETA" in err  # the same progress in the terminal


def _fake_run(fail_at: dict[int, BaseException], calls: list[int]):
    """A stand-in for the pipeline: records the rally it ran; raises ``fail_at[k]`` on the k-th rally."""
    def run(clip, cfg, only=None, log=print):
        k = int(clip.root.name.split("_")[1])
        calls.append(k)
        if k in fail_at:
            raise fail_at[k]
        return PipelineReport(clip, [StageReport("scenes", "done", 0.1, clip.n_frames)])
    return run


def test_match_resumes_after_an_interruption_and_goes_on_after_a_failure(match_video, tmp_path, monkeypatch):
    from inference.pipeline.stages import PipelineConfig

    video, _ = match_video
    out, cfg = tmp_path / "m", PipelineConfig(pose="none", progress=False)
    calls: list[int] = []
    code = M.run_match(video, out, "tennis", cfg, quiet=True, run_one=_fake_run({2: KeyboardInterrupt()}, calls))
    assert code == 130 and calls == [1, 2]
    index = M.MatchIndex.read(out / M.MATCH_FILE)
    assert [r.status for r in index.rallies] == ["done", "interrupted", "pending"]
    video_mtime = (out / "rally_001" / "video.mp4").stat().st_mtime_ns

    def no_scan(*a, **k):
        raise AssertionError("a resumed run must not scan the match again")

    monkeypatch.setattr(M, "scan_video", no_scan)
    calls.clear()
    code = M.run_match(video, out, "tennis", cfg, quiet=True, run_one=_fake_run({}, calls))
    assert code == 0 and calls == [2, 3]  # the done rally is not run again
    assert (out / "rally_001" / "video.mp4").stat().st_mtime_ns == video_mtime
    assert "resuming" in (out / M.LOG_FILE).read_text()
    monkeypatch.undo()

    # other stages (--only) than the last run: every rally runs again; --rallies picks some
    calls.clear()
    assert M.run_match(video, out, "tennis", cfg, only={"scenes"}, rallies={3}, quiet=True,
                       run_one=_fake_run({}, calls)) == 0 and calls == [3]
    assert [r.status for r in M.MatchIndex.read(out / M.MATCH_FILE).rallies] == ["pending", "pending", "done"]
    with pytest.raises(ValueError, match="the match has rallies 1–3"):
        M.run_match(video, out, "tennis", cfg, only={"scenes"}, rallies={4}, quiet=True, run_one=_fake_run({}, calls))
    assert M.parse_rallies("1-3,7") == {1, 2, 3, 7}
    with pytest.raises(ValueError, match="like 3 or 1-3,7"):
        M.parse_rallies("3-1")

    # a failing rally is recorded with its reason; the next one still runs
    calls.clear()
    out2 = tmp_path / "m2"
    code = M.run_match(video, out2, "tennis", cfg, quiet=True,
                       run_one=_fake_run({2: RuntimeError("the detector ran out of memory\ntraceback…")}, calls))
    assert code == 1 and calls == [1, 2, 3]
    with open(out2 / M.INDEX_FILE, newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["status"] for r in rows] == ["done", "failed", "done"]
    assert rows[1]["note"] == "the detector ran out of memory"


def test_a_match_with_no_court_view_long_enough_says_so(match_video, tmp_path, capsys):
    video, _ = match_video
    out = tmp_path / "none"
    assert main(["infer", str(video), "--match", "--court", "tennis", "--only", "scenes", "--min-rally", "30",
                 "--max-rally", "90", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "no rally found" in err and "no court view of 30 s or more" in err and "--whole" in err


def test_a_long_video_is_a_match_unless_whole(match_video, tmp_path, monkeypatch, capsys):
    from inference.pipeline import cli

    video, truth = match_video
    monkeypatch.setattr(cli, "MATCH_ABOVE_S", 10.0)  # the test video is 21 s long
    out = tmp_path / "auto"
    assert main(["infer", str(video), "--court", "tennis", "--only", "scenes", "--out", str(out)]) == 0
    assert "treated as a match" in capsys.readouterr().err and (out / M.INDEX_FILE).is_file()
    whole = tmp_path / "whole"
    assert main(["infer", str(video), "--whole", "--court", "tennis", "--only", "scenes", "--out", str(whole)]) == 0
    assert not (whole / M.INDEX_FILE).exists() and Clip(whole).n_frames == truth[-1][2]
    capsys.readouterr()
    assert main(["infer", str(video), "--match", "--start", "2", "--court", "tennis", "--out", str(tmp_path / "x")]) != 0
    assert "--match splits a whole video into rallies; leave out --whole, --start and --end" in capsys.readouterr().err
