"""Interrupted work never becomes silent bad data: a generation stopped by Ctrl-C is never read as a dataset
(the next run resumes it, saying so), a resumed generation ends as a whole dataset, and an interrupted frame
cache build leaves nothing that is read."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys

import numpy as np
import pytest
from conftest import wait_until
from training_fixtures import ROOT, compose_cfg, tiny_padel  # noqa: F401  (fixtures)

import synth.generate as generate
from training.datasets import resolve_source
from training.preflight import PARTIAL, check_data, default_dataset_state, generate_default
from synth.generate import SynthConfig, generate_dataset
from synth.partial import read_marker

TINY = {"randomise_camera": False, "width": 160, "height": 96, "codec": "mp4v", "randomise_look": False}
REAL_CLIP = generate.generate_clip
GENERATE = "import json, sys; from training.preflight import generate_default; generate_default(sys.argv[1], json.loads(sys.argv[2]))"


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}


def _stopping_after(n_new: int, seeds: list[int]):
    """A ``generate_clip`` that records the seeds it renders and raises KeyboardInterrupt (Ctrl-C) while rendering
    clip ``n_new + 1`` of this call, after ``n_new`` clips."""
    start = len(seeds)

    def clip(out, seed, config=None, progress=None):
        if len(seeds) - start == n_new:
            raise KeyboardInterrupt
        seeds.append(seed)
        return REAL_CLIP(out, seed, config, progress)

    return clip


def _marked_done(root) -> dict:
    """The clips the generation's progress marker records as made ({} while there is none)."""
    return (read_marker(root) or {}).get("done") or {}


def test_ctrl_c_during_generation_is_resumed_never_trained_on(tmp_path, monkeypatch, capsys):
    """The first command's generation (training.preflight.generate_default) in its own process, Ctrl-C once its
    first clip is there: no manifest.yaml; the next run does not take the clips it left for a dataset, it
    generates again, resuming (the clips made are kept, a line says so); a plain data.root= pointing at it stops."""
    root = tmp_path / "data" / "synth_padel"
    spec = {"sport": "padel", "clips": 100, "seed": 3, "max_frames": 12, "config": TINY}
    log = tmp_path / "generate.log"
    with log.open("w") as f:
        # Ctrl-C must reach the child even when this test runs in the background (`make test &`: a
        # non-interactive shell starts background jobs with SIGINT ignored, and children inherit that)
        proc = subprocess.Popen([sys.executable, "-c", GENERATE, str(root), json.dumps(spec)], cwd=ROOT, env=_env(),
                                stdout=f, stderr=subprocess.STDOUT,
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        try:
            # the first clip in place *and* recorded as made (the marker is written just after the clip is moved
            # into place: a Ctrl-C between the two leaves it to be made again, which is right but made = 0 below)
            wait_until(lambda: proc.poll() is not None or ((root / "clip_0000" / "clip.yaml").is_file()
                                                           and "clip_0000" in _marked_done(root)),
                       what=f"the first clip folder under {root}, recorded as made")
            assert proc.poll() is None, log.read_text()[-3000:]
            proc.send_signal(signal.SIGINT)                       # Ctrl-C
            proc.wait(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
    assert proc.returncode != 0 and not (root / "manifest.yaml").exists(), log.read_text()[-3000:]
    assert list(root.glob("*/clip.yaml"))                         # what used to pass for a dataset

    cfg = compose_cfg(["+experiment=wasb_padel", f"paths.data_dir={tmp_path / 'data'}"], tmp_path / "run")
    calls = []
    assert check_data(cfg, generate=lambda r, s: calls.append(r)) == [str(root)] and calls == [str(root)]
    assert re.match(r"is an unfinished `rally3d synth --sport padel --clips 100 --seed 3` \(\d+ of 100 clips made",
                    default_dataset_state(root) or "")
    other = compose_cfg(["+experiment=wasb_padel", f"data.root={root}"], tmp_path / "run")  # not the default folder
    with pytest.raises(SystemExit, match=r"unfinished .*run the same generation again into .*resumes"):
        check_data(other, generate=lambda r, s: pytest.fail("must not generate"))
    with pytest.raises(FileNotFoundError, match="unfinished"):
        resolve_source(root)

    seeds: list[int] = []
    monkeypatch.setattr(generate, "generate_clip", _stopping_after(1, seeds))
    with pytest.raises(KeyboardInterrupt):
        generate_default(root, spec)                                # the next run resumes (stopped again here)
    said = capsys.readouterr().out
    made = int(re.search(r"resuming an interrupted generation: (\d+) of 100 clips already made", said)[1])
    assert "synth_padel is an unfinished `rally3d synth --sport padel --clips 100 --seed 3`" in said
    assert 1 <= made < 100 and seeds == [3 * 100003 + made]       # the first clip not made yet, no clip made twice


def test_a_resumed_generation_ends_whole_and_other_settings_start_again(tmp_path, monkeypatch, capsys):
    out = tmp_path / "synth"
    config = SynthConfig(sport="padel", max_frames=10, **TINY)
    seeds: list[int] = []
    monkeypatch.setattr(generate, "generate_clip", _stopping_after(1, seeds))
    with pytest.raises(KeyboardInterrupt):
        generate_dataset(out, 3, seed=7, config=config)
    assert (out / PARTIAL).is_file() and not (out / "manifest.yaml").exists()
    assert sorted(p.parent.name for p in out.glob("*/clip.yaml")) == ["clip_0000"]  # clip_0001: not in place
    with pytest.raises(FileNotFoundError, match=r"unfinished `rally3d synth --sport padel --clips 3 --seed 7` "
                                                r"\(1 of 3 clips made"):
        resolve_source(out)

    monkeypatch.setattr(generate, "generate_clip", _stopping_after(10, seeds))
    manifest = generate_dataset(out, 3, seed=7, config=config)
    assert "resuming an interrupted generation: 1 of 3 clips already made" in capsys.readouterr().out
    assert seeds == [7 * 100003 + k for k in range(3)]            # each clip rendered once over both runs
    assert [c.path for c in manifest.clips] == ["clip_0000", "clip_0001", "clip_0002"]
    assert not (out / PARTIAL).exists() and not (out / ".partial").exists()
    assert resolve_source(out).manifest.counts() == manifest.counts()

    seeds.clear()
    monkeypatch.setattr(generate, "generate_clip", _stopping_after(0, seeds))
    with pytest.raises(KeyboardInterrupt):
        generate_dataset(out, 3, seed=8, config=config)            # a new generation into it, stopped at once
    assert not (out / "manifest.yaml").exists()                    # the old manifest no longer vouches for it
    monkeypatch.setattr(generate, "generate_clip", _stopping_after(10, seeds))
    generate_dataset(out, 2, seed=9, config=config)
    assert "with other settings was here: making every clip again" in capsys.readouterr().out
    assert seeds == [9 * 100003, 9 * 100003 + 1]


def test_an_interrupted_frame_cache_is_never_read(tiny_padel, tmp_path, monkeypatch):
    """Ctrl-C while the letterboxed frames of a clip are cached: nothing under the cache's name (and no
    temporary file); the next load builds the whole cache."""
    from inference.clipio import Clip
    from training.detection import data

    clip = Clip(tiny_padel / "clip_0000")
    cache = tmp_path / "cache"
    warp = data.Letterbox.warp
    count = [0]

    def stopping(self, frame):
        count[0] += 1
        if count[0] == 5:
            raise KeyboardInterrupt
        return warp(self, frame)

    monkeypatch.setattr(data.Letterbox, "warp", stopping)
    with pytest.raises(KeyboardInterrupt):
        data.load_clip(clip, (64, 112), cache)
    assert not list(cache.iterdir())
    monkeypatch.setattr(data.Letterbox, "warp", warp)
    loaded = data.load_clip(clip, (64, 112), cache)
    assert len(loaded.frames) == clip.n_frames and np.asarray(loaded.frames[-1]).any()
    assert [p.suffix for p in cache.iterdir()] == [".npy"]
