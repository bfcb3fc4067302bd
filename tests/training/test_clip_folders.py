"""A folder of clip folders, as annotators leave it (gaps, partial labels, a tracker's missing rows, 25–60 fps,
256×144 to 4K, clips not labelled yet, no manifest), is a dataset: detector and hit-event training run,
export and evaluate on it; unlabelled frames are not negatives; mixed roots follow their weights; a
failing test table never loses the trained model."""
from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from training_fixtures import compose_cfg, labeler_clips, small_detector, tiny_padel  # noqa: F401  (fixtures)

from inference.clipio import Clip
from inference.events import EventDetector
from inference.models.checkpoint import META_KEY, read_checkpoint
from training.datasets import ball_input, infer_manifest, resolve_sources
from training.run import evaluate, train


def test_a_folder_of_clips_gets_a_seeded_split_by_clip_or_match(labeler_clips):
    m = infer_manifest(labeler_clips, seed=3)
    names = sorted(c.path for c in m.clips)
    assert names == ["a_25fps", "b_partial", "c_60fps_4k", "d_30fps", "e_unlabelled"]
    split = {c.path: c.split for c in m.clips}
    assert split["c_60fps_4k"] == split["d_30fps"]            # same clip.yaml match → same split
    assert {"train", "val", "test"} <= set(split.values())    # four groups: every split gets one
    assert {c.path: c.split for c in infer_manifest(labeler_clips, seed=3).clips} == split  # seeded
    assert not (labeler_clips / "manifest.yaml").exists()     # nothing written into the user's folder
    with pytest.raises(FileNotFoundError, match="no clip folders"):
        infer_manifest(labeler_clips / "a_25fps" / "gt_missing")


def test_unlabelled_frames_are_left_out_of_the_loss(labeler_clips, tmp_path):
    from training.detection.data import BallDataModule
    from training.detection.losses import HeatmapLoss

    dm = BallDataModule(train_clips=[str(labeler_clips / "b_partial")], net_size=(64, 112), crop=None,
                        augment=False, cache_dir=str(tmp_path / "cache"))
    ds = dm._windows("train")
    assert Clip(labeler_clips / "b_partial").read_ball().frame.max() == 17
    assert max(s for _, s in ds.index) == 17  # no window made only of frames the annotator never touched
    # the window straddling the end of the labels: its last frame is unlabelled, not "no ball"
    edge = next(i for i, (_, s) in enumerate(ds.index) if s == 16)
    x, y, meta = ds[edge]
    vis = meta["visibility"]
    assert vis[2] == -1 and not meta["labelled"][2]
    assert meta["labelled"].tolist() == ((vis >= 0) & (vis != 3)).tolist()
    loss = HeatmapLoss("wbce")
    logits = torch.zeros(1, *y.shape)
    base = loss(logits, y[None], meta["labelled"][None])
    logits[0, 2] = 8.0  # "a ball everywhere" on the unlabelled frame: no penalty
    assert torch.isclose(loss(logits, y[None], meta["labelled"][None]), base)
    assert loss(logits, y[None]) > base  # without the mask it would be punished as a negative
    # an occluded (visibility 3) frame is left out like an unlabelled one
    a = BallDataModule(train_clips=[str(labeler_clips / "a_25fps")], net_size=(64, 112), augment=False,
                       cache_dir=str(tmp_path / "cache"))._windows("train")
    track = Clip(labeler_clips / "a_25fps").read_ball()
    f3 = int(track.frame[track.visibility == 3][0])
    meta = next(a[i][2] for i, (_, s) in enumerate(a.index) if s == f3 - 2)
    assert meta["visibility"][2] == 3 and not meta["labelled"][2]
    assert not any(s in range(20, 24) for _, s in a.index)  # windows inside the gap (frames 20–25) do not exist


def test_detector_trains_exports_and_evaluates_on_labeler_folders(labeler_clips, tmp_path):
    cfg = compose_cfg(["+experiment=wasb_padel", "trainer.max_epochs=1", "trainer.limit_train_batches=2",
                       "trainer.limit_val_batches=1", "trainer.limit_test_batches=1",
                       *small_detector(labeler_clips, tmp_path / "cache")], tmp_path / "run")
    metrics = train(cfg)
    assert "val/f1" in metrics and "test/f1" in metrics
    model = tmp_path / "run" / "wasb.pth.tar"
    stored = read_checkpoint(model)[META_KEY]
    assert stored == {"arch": "wasb", "frames_in": 3, "frames_out": 3, "normalize": "imagenet", "input_size": [64, 112]}
    assert read_checkpoint(tmp_path / "run" / "checkpoints" / "last.ckpt")[META_KEY]["normalize"] == "imagenet"
    saved = list((tmp_path / "run").glob("manifest_*_my_clips.yaml"))
    assert len(saved) == 1 and "e_unlabelled" in saved[0].read_text()

    ev = compose_cfg(["+experiment=wasb_padel", f"ckpt_path={model}", f"data.root={labeler_clips}",
                      "data.net_size=[64,112]", f"data.cache_dir={tmp_path}/cache"], tmp_path / "eval", name="eval")
    scores = evaluate(ev)
    assert {"f1_tau4_tracker", "f1_tau10_max-score"} <= set(scores)
    blob = json.loads((tmp_path / "eval" / "results.json").read_text())
    rows = blob["rows"]
    assert {r["split"] for r in rows} == {"all"}  # a folder without manifest: every labelled clip
    # the per-visibility table counts exactly the rows annotators wrote (tiny synthetic balls are "hard", 2)
    labelled = np.concatenate([Clip(labeler_clips / n).read_ball().visibility
                               for n in ("a_25fps", "b_partial", "c_60fps_4k", "d_30fps")])
    per_vis = {r["class"]: r["frames"] for r in rows if r["table"] == "per_visibility_tau10"}
    assert per_vis == {"hard to see (2)": int((labelled == 2).sum()), "occluded (3)": int((labelled == 3).sum())}
    assert all(r["ball_input"] == "annotated (4 clips)" for r in rows if "ball_input" in r)  # e has no ball.csv
    csv_head = (tmp_path / "eval" / "results.csv").read_text().splitlines()[0].split(",")
    assert {"model", "checkpoint", "class", "f1", "precision", "recall"} <= set(csv_head)
    assert blob["config"]["ckpt_path"] == str(model)


def test_hit_events_train_export_and_evaluate_on_labeler_folders(labeler_clips, tmp_path):
    """From the shipped model (hitnet_padel_finetune) on real-style clips: c has a tracker's ball.csv with
    missing rows (the reviewed crash happened in a table that degraded such a track), e has no ball.csv."""
    cfg = compose_cfg(["+experiment=hitnet_padel_finetune", f"data.root={labeler_clips}", "trainer.max_epochs=1",
                       "trainer.limit_train_batches=2", "data.batch_size=16", "data.split_seed=3",
                       "degraded_rows=true"], tmp_path / "run")
    metrics = train(cfg)
    model = tmp_path / "run" / "hitnet_padel.pth.tar"
    det = EventDetector.from_checkpoint(model)
    assert det.class_set.name == "padel6" and "test" in det.meta
    assert "events/gt_f1" in metrics and "events/deg_f1" in metrics  # degraded rows when asked, no crash
    rows = json.loads((tmp_path / "run" / "results.json").read_text())["rows"]
    assert {r["table"] for r in rows} == {"gt", "e2e", "deg"}
    assert any(r["ball_input"].startswith("ball.csv: annotated") for r in rows)

    ev = compose_cfg(["+experiment=hitnet_padel", "data.source=folder", f"data.root={labeler_clips}",
                      f"ckpt_path={model}"], tmp_path / "eval", name="eval")
    scores = evaluate(ev)
    assert "events/gt_f1" in scores and "events/e2e_f1" not in scores  # real clips: no synthetic rows by default
    rows = json.loads((tmp_path / "eval" / "results.json").read_text())["rows"]
    assert {r["class"] for r in rows} == {"all", *det.class_set.classes[1:]}  # per-class table, every class
    assert sum(r["n_gt"] for r in rows if r["class"] != "all") == next(r["n_gt"] for r in rows if r["class"] == "all")
    assert {r["split"] for r in rows} == {"all"}


def test_ball_input_says_what_ball_csv_is(labeler_clips, tmp_path):
    import shutil

    from inference.pipeline.state import RunState

    clip = Clip(shutil.copytree(labeler_clips / "d_30fps", tmp_path / "d"))
    assert ball_input(clip) == "annotated"
    RunState(clip.root).record("smooth", "k", "done", [clip.ball_path], 0.1)  # as rally3d infer leaves it
    assert ball_input(clip) == "detector"
    assert ball_input(clip, "tracker") == "tracker"


def test_mixed_roots_follow_their_weights(labeler_clips, tiny_padel, tmp_path):
    from training.detection.data import BallDataModule

    dm = BallDataModule(root=[str(labeler_clips), str(tiny_padel)], root_weights=[3, 1], net_size=(64, 112),
                        crop=(32, 32), cache_dir=str(tmp_path / "cache"), seed=1)
    assert [s.inferred for s in dm.sources] == [True, False]
    dm.setup("fit")
    w = dm.sample_weights()
    src = dm.window_source["train"]
    assert set(src.tolist()) == {0, 1} and np.isclose(w[src == 0].sum(), 0.75)
    drawn = np.array(list(iter(dm.train_dataloader().sampler)))
    assert abs(np.mean(src[drawn] == 0) - 0.75) < 0.08
    with pytest.raises(ValueError, match="one per root"):
        resolve_sources([str(labeler_clips), str(tiny_padel)], weights=[1])


def test_a_failing_test_table_keeps_the_trained_model(labeler_clips, tmp_path, monkeypatch, capsys):
    """Fault injection: the test tables raise after training; the model files exist and load."""
    import training.events.run as events_run
    import training.run as run

    def broken(*a, **k):
        raise RuntimeError("injected failure in the test table")

    monkeypatch.setattr(events_run, "event_tables", broken)
    cfg = compose_cfg(["+experiment=hitnet_padel", "data.source=folder", f"data.root={labeler_clips}",
                       "trainer.max_epochs=1", "trainer.limit_train_batches=2", "data.batch_size=16"],
                      tmp_path / "events")
    metrics = train(cfg)
    assert metrics["test/failed"] == 1.0 and "injected failure" in capsys.readouterr().out
    assert EventDetector.from_checkpoint(tmp_path / "events" / "hitnet_padel.pth.tar").net is not None

    monkeypatch.setattr(run, "_test", broken)
    cfg = compose_cfg(["+experiment=wasb_padel", "trainer.max_epochs=1", "trainer.limit_train_batches=1",
                       "trainer.limit_val_batches=1", *small_detector(labeler_clips, tmp_path / "cache")],
                      tmp_path / "det")
    metrics = train(cfg)
    assert metrics["test/failed"] == 1.0
    assert read_checkpoint(tmp_path / "det" / "wasb.pth.tar")[META_KEY]["arch"] == "wasb"
    assert (tmp_path / "det" / "checkpoints" / "last.ckpt").is_file()
