"""Every hitnet* and tagger* experiment composes and runs (fast_dev_run) like ``python train.py +experiment=NAME``;
tennis trains from a dataset converted from a TrackNet ``Label.csv``; bad data gives clear errors."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import compose_cfg
import torch

from inference.clipio import Clip, ClipInfo, HitEvents, Manifest, ManifestEntry
from inference.events import ClassSet, EventDetector, UnmappedLabelError
from inference.events.features import FeatureConfig
from training.events.data.datamodule import AugmentConfig, augment_batch
from training.events.synthetic.simulate import simulate_clip
from training.events.data.tracknet import convert_tracknet_dataset
from training.run import evaluate, train

ROOT = Path(__file__).resolve().parents[3]
HITNET_EXPERIMENTS = sorted(p.stem for pattern in ("hitnet*.yaml", "tagger*.yaml")
                            for p in (ROOT / "conf" / "experiment").glob(pattern))
TINY = ["data.n_train=3", "data.n_val=2", "data.n_test=2", "data.batch_size=32", "trainer.accelerator=cpu"]


@pytest.mark.parametrize("experiment", HITNET_EXPERIMENTS)
def test_hitnet_experiment_fast_dev_run(experiment, tmp_path):
    # *_finetune experiments read your clip folders (tests/training/test_clip_folders.py); here: simulated data
    data = ["data.source=synthetic"] if experiment.endswith("_finetune") else []
    cfg = compose_cfg([f"+experiment={experiment}", "trainer.fast_dev_run=true", *TINY, *data,
                       f"data.cache_dir={tmp_path}/cache"], tmp_path)
    tagger = experiment.startswith("tagger")
    assert cfg.task == "events" and cfg.model._target_.endswith("TaggerModule" if tagger else "HitNetModule")
    metrics = train(cfg)
    assert torch.isfinite(torch.tensor(metrics["train/loss_step"]))
    assert 0.05 <= metrics["events/temperature"] <= 20
    sport = cfg.data.sport  # hitnet_padel, hitnet_crop_padel, hitnet_padel_finetune: the file is named by sport
    model = tmp_path / f"{'tagger' if tagger else 'hitnet'}_{sport}.pth.tar"
    det = EventDetector.from_checkpoint(model)  # the exported file loads without the config
    assert det.class_set.sport == sport and det.net is not None and det.kind == ("tagger" if tagger else "crop" if "crop" in experiment else "hitnet")
    assert "events/gt_f1" in metrics and "events/e2e_f1" in metrics
    ev = compose_cfg([f"+experiment={experiment}", *TINY, *data, f"data.cache_dir={tmp_path}/cache",
                      f"ckpt_path={model}"], tmp_path / "e", name="eval")
    scores = evaluate(ev)
    assert set(scores) >= {"events/gt_f1", "events/e2e_recall"}


def _write_label_csv(path: Path, n: int, hits: dict[int, int], rng) -> None:
    rows = ["file name,visibility,x-coordinate,y-coordinate,status"]
    for i in range(n):
        if i % 17 == 5:
            rows.append(f"{i:04d}.jpg,0,,,0")
            continue
        x, y = 300 + 5 * i + rng.normal(0, 1), 200 + 120 * np.sin(i / 9) + rng.normal(0, 1)
        rows.append(f"{i:04d}.jpg,1,{x:.1f},{y:.1f},{hits.get(i, 0)}")
    path.write_text("\n".join(rows) + "\n")


def test_tennis_trains_on_a_converted_tracknet_label_csv(tmp_path):
    rng = np.random.default_rng(0)
    files = {}
    for split in ("train", "val", "test"):
        f = tmp_path / f"{split}_Label.csv"
        _write_label_csv(f, 90, {12: 1, 30: 2, 48: 1, 66: 2, 80: 1}, rng)
        files[split] = [f]
    root = tmp_path / "tracknet_events"
    convert_tracknet_dataset(files, root, fps=30, width=1280, height=720)
    clip = Clip(Manifest.load(root).paths("train")[0])
    events = clip.read_events()
    assert events.frame.tolist() == [12, 30, 48, 66, 80]
    assert set(events.event.tolist()) <= {"ground", "player_near", "player_far"} and "ground" in events.event
    cfg = compose_cfg(["+experiment=hitnet_tennis", "trainer.fast_dev_run=true", "data.source=folder",
                       f"data.root={root}", "data.batch_size=16", "trainer.accelerator=cpu"], tmp_path / "run")
    metrics = train(cfg)
    assert np.isfinite(metrics["train/loss_step"])
    assert metrics["events/gt_f1"] >= 0.0


def _dataset(root: Path, events: HitEvents, n: int = 60) -> Path:
    sim = simulate_clip("padel", 3)
    entries = []
    for split in ("train", "val", "test"):
        clip = Clip.create(root / split, ClipInfo(sport="padel", fps=sim.fps, width=sim.width, height=sim.height,
                                                  video="video.mp4", n_frames=n, split=split), exist_ok=True)
        track = sim.ball
        keep = track.frame < n
        from inference.clipio import BallTrack

        clip.write_ball(BallTrack(track.frame[keep], track.visibility[keep], track.xy[keep]))
        clip.write_events(events)
        entries.append(ManifestEntry(split, split))
    Manifest(root, entries, name="bad", sport="padel").save()
    return root


def test_a_class_set_not_covering_a_label_is_an_error(tmp_path):
    root = _dataset(tmp_path / "ds", HitEvents([10, 20, 30], ["ground", "player_near", "wall_near"]))
    cfg = compose_cfg(["+experiment=hitnet_padel", "trainer.fast_dev_run=true", "data.source=folder",
                       f"data.root={root}", "data.class_set=tennis4"], tmp_path / "run")
    cfg_ok = compose_cfg(["+experiment=hitnet_padel", "data.source=folder", f"data.root={root}"], tmp_path / "r2")
    with pytest.raises(UnmappedLabelError, match="does not cover"):
        from training.run import build

        dm, _, _ = build(cfg)
        dm.setup("fit")
    from training.run import build

    dm, _, _ = build(cfg_ok)
    dm.setup("fit")
    assert int((dm.sets["train"].y > 0).sum()) > 0


def test_clips_without_events_cannot_train(tmp_path):
    root = _dataset(tmp_path / "ds", HitEvents.empty())
    cfg = compose_cfg(["+experiment=hitnet_padel", "trainer.fast_dev_run=true", "data.source=folder",
                       f"data.root={root}", "trainer.accelerator=cpu"], tmp_path / "run")
    with pytest.raises(ValueError, match="no events"):
        train(cfg)


def test_augmentation_mirrors_positions_and_swaps_wall_labels():
    d = ClassSet.load("padel6").to_dict()
    d.update(name="walls", classes=["none", "wall_left", "wall_right", "player_near", "player_far"],
             map={k: k for k in ("wall_left", "wall_right", "player_near", "player_far")},
             default_fine={}, resolve_with_camera={})
    d["rules"]["requires_last_hit"] = {}
    cs = ClassSet.from_dict(d)
    fc = FeatureConfig()
    x = torch.zeros(4, 12, 5)
    x[:, :, 0], x[:, :, 1], x[:, :, 4] = 1.2, 1.7, 1.0
    x[:, 3, :] = 0  # a missing frame stays missing
    y = torch.tensor([1, 2, 3, 0])
    aug = AugmentConfig(weights=(1, 0, 0, 0, 0, 0, 0, 0, 0, 0), p_mirror=1.0)
    xa, ya = augment_batch(x, y, fc, aug, torch.as_tensor(cs.mirror_permutation()))
    assert ya.tolist() == [2, 1, 3, 0]
    assert torch.allclose(xa[:, 0, 0], torch.tensor(1.8)) and torch.allclose(xa[:, 0, 1], torch.tensor(1.7))
    assert torch.all(xa[:, 3] == 0)
