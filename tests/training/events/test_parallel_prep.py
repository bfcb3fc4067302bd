"""Per-clip data work in forked processes (training/events/data/parallel.py): the same data as in one process."""
from __future__ import annotations

import signal

import numpy as np
import pytest

from training.events.data.datamodule import EventDataModule
from training.events.synthetic.degrade import DegradeConfig, degrade_all
from training.events.data.parallel import can_fork, clip_rngs, map_clips
from training.events.synthetic.simulate import simulate_clips

pytestmark = pytest.mark.skipif(not can_fork(), reason="no fork on this platform: the work runs in one process")


def test_map_clips_keeps_order_and_draws_per_clip():
    rngs = clip_rngs(7, 23)
    draws = [r.random() for r in clip_rngs(7, 23)]

    def job(k: int) -> tuple[int, float]:
        return k, float(rngs[k].random())

    out = map_clips(job, 23, workers=3)
    assert [k for k, _ in out] == list(range(23))
    assert np.allclose([v for _, v in out], draws)
    assert map_clips(job, 0, workers=3) == []


def test_workers_ignore_the_parents_signal_handlers():
    """A training run's SIGTERM handler raises in the parent; forked workers must not inherit it (the pool's
    shutdown sends them SIGTERM: with the handler they hung, and the epoch with them)."""
    def raising(signum, frame):
        raise KeyboardInterrupt(f"signal {signum}")

    def handlers(_k: int) -> tuple:
        return signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGINT)

    old = signal.signal(signal.SIGTERM, raising)
    try:
        seen = set(map_clips(handlers, 8, workers=2))
        assert seen == {(signal.SIG_DFL, signal.SIG_IGN)}, seen
        assert map_clips(lambda k: k * k, 40, workers=2) == [k * k for k in range(40)]
        assert signal.getsignal(signal.SIGTERM) is raising  # the parent keeps its own
    finally:
        signal.signal(signal.SIGTERM, old)


def test_simulation_and_degradation_are_the_same_with_workers(tmp_path):
    one = simulate_clips("tennis", 4, 4321, None, progress=False)
    many = simulate_clips("tennis", 4, 4321, None, progress=False, workers=2)
    for a, b in zip(one, many):
        assert a.name == b.name and a.n_frames == b.n_frames
        assert np.array_equal(a.ball.xy, b.ball.xy, equal_nan=True)
    cfg = DegradeConfig.from_dict({"enabled": True, "p_clean": 0.0})
    for a, b in zip(degrade_all(one, 5, cfg), degrade_all(one, 5, cfg, workers=2)):
        assert np.array_equal(a.visibility, b.visibility)
        assert np.array_equal(a.xy, b.xy, equal_nan=True)


def _module(workers: int, cache) -> EventDataModule:
    return EventDataModule(sport="tennis", class_set="tennis4", features={"poses": True}, n_train=6, n_val=2,
                           n_test=2, seed=3, on_unmapped="warn", cache_dir=str(cache), sequence=64,
                           degrade={"enabled": True, "p_clean": 0.0}, pose_noise={"enabled": True},
                           prep_workers=workers)


def test_data_module_gives_the_same_crops_with_prep_workers(tmp_path):
    """Labelling, the first draw and each epoch's new tracks and players: identical features."""
    serial, forked = _module(0, tmp_path), _module(2, tmp_path)
    for dm in (serial, forked):
        dm.setup("fit")
        dm.redraw()
        dm.redraw()  # the second call draws new tracks and players
    for split in ("train", "val"):
        a, b = serial.sets[split].clips, forked.sets[split].clips
        assert len(a) == len(b) > 0
        for x, y in zip(a, b):
            assert np.array_equal(x.feats, y.feats) and np.array_equal(x.y, y.y)
    first = _module(2, tmp_path)
    first.setup("fit")
    changed = [not np.array_equal(x.feats, y.feats) for x, y in zip(first.sets["train"].clips,
                                                                    forked.sets["train"].clips)]
    assert any(changed), "the redraw should give new degraded tracks"


def test_prep_workers_must_not_be_negative():
    with pytest.raises(ValueError, match="prep_workers"):
        EventDataModule(sport="tennis", class_set="tennis4", prep_workers=-1)
