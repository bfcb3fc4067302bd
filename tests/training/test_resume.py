"""A resumed run (``ckpt_path=PATH`` or ``ckpt_path=last``) continues where it left: in the run folder of its
checkpoint (checkpoints, CSV log, exported model file, results), with its best-checkpoint state — a worse
epoch after the resume never becomes the best, and the exported model is the best of the whole run. An
explicit choice (``resume_new_folder=true``, ``paths.output_dir=``, ``hydra.run.dir=``), a debug run or a
checkpoint outside a run folder keeps a new folder, and every choice is said in one log line."""
from __future__ import annotations

import csv
import logging
from pathlib import Path

import pytest
import torch
from omegaconf import open_dict
from training_fixtures import compose_cfg, small_detector, tiny_padel  # noqa: F401  (fixtures)

CONTINUED_NOTE, RESUMES_LOG = "continued_in.txt", "resumes.log"  # training.common's names, spelled as the docs do
SCRIPTED_F1 = {0: 0.8, 1: 0.3}  # the resumed epoch (1) is worse than the first (0)


def _as_cli(cfg, hydra_dir: Path):
    """What ``python train.py …`` composes: ``paths.output_dir`` is Hydra's run folder (compose_cfg sets a
    literal, as an explicit ``paths.output_dir=`` would), and Hydra writes ``.hydra/overrides.yaml``."""
    import yaml
    from hydra.core.hydra_config import HydraConfig

    assert Path(HydraConfig.get().runtime.output_dir) == hydra_dir  # compose_cfg(…, hydra_dir) set it
    with open_dict(cfg):
        cfg.paths.output_dir = "${hydra:runtime.output_dir}"
    (hydra_dir / ".hydra").mkdir(parents=True, exist_ok=True)
    (hydra_dir / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump(list(cfg.hydra.overrides.task)))
    return cfg


def _val_rows(metrics_csv: Path) -> list[dict]:
    with metrics_csv.open(newline="") as f:
        return [r for r in csv.DictReader(f) if r.get("val/f1")]


def test_a_resumed_run_continues_in_its_folder_with_its_best_checkpoint(tiny_padel, tmp_path, monkeypatch, caplog):
    """Train 1 epoch (val/f1 scripted 0.8), resume with ``ckpt_path=last`` for a worse epoch (0.3): the second
    run writes into the first run's folder, the CSV log holds both epochs, the best stays epoch 1's and the
    exported model file holds its weights (the original file kept as ``.bak``)."""
    from lightning.pytorch.callbacks import ModelCheckpoint

    import training.run as run_mod
    from inference.models.checkpoint import load_weights, read_checkpoint

    monitor = ModelCheckpoint._monitor_candidates

    def scripted(self, trainer):  # a validation F1 per epoch that does not depend on the tiny model's luck
        out = monitor(self, trainer)
        out["val/f1"] = torch.tensor(SCRIPTED_F1[trainer.current_epoch])
        return out

    monkeypatch.setattr(ModelCheckpoint, "_monitor_candidates", scripted)
    trainers = []

    def spy(cfg):
        dm, model, trainer = build(cfg)
        trainers.append(trainer)
        return dm, model, trainer

    build = run_mod.build
    monkeypatch.setattr(run_mod, "build", spy)
    logs = tmp_path / "runs"
    common = ["+experiment=wasb_padel", *small_detector(tiny_padel, tmp_path / "cache"),
              "trainer.limit_train_batches=2", "trainer.limit_val_batches=1", "test=false", "progress_bar=false",
              f"paths.log_dir={logs}"]
    first, second = logs / "train" / "runs" / "first", logs / "train" / "runs" / "second"
    run_mod.train(_as_cli(compose_cfg([*common, "trainer.max_epochs=1"], first), first))
    original = (first / "wasb.pth.tar").read_bytes()
    assert trainers[0].checkpoint_callback.best_model_score == pytest.approx(0.8)

    caplog.set_level(logging.INFO, logger="training.run")
    run_mod.train(_as_cli(compose_cfg([*common, "trainer.max_epochs=2", "ckpt_path=last"], second), second))
    # everything the resumed run writes is in the first run's folder; Hydra's new folder only points there
    assert not (second / "checkpoints").exists() and not (second / "csv").exists()
    assert not list(second.glob("*.pth.tar")) and str(first) in (second / CONTINUED_NOTE).read_text()
    assert "resumed from" in (first / RESUMES_LOG).read_text()
    assert read_checkpoint(first / "checkpoints" / "last.ckpt")["epoch"] == 1  # the second epoch's state
    assert sorted(p.name for p in (first / "csv").iterdir()) == ["version_0"]
    assert [int(r["epoch"]) for r in _val_rows(first / "csv" / "version_0" / "metrics.csv")] == [0, 1]
    # the best-checkpoint state is the original run's: the worse epoch 2 did not replace it
    cb = trainers[1].checkpoint_callback
    assert cb.best_model_score == pytest.approx(0.8)
    assert Path(cb.best_model_path) == first / "checkpoints" / "epoch_000.ckpt"
    assert sorted(p.name for p in (first / "checkpoints").glob("epoch_*.ckpt")) == ["epoch_000.ckpt"]
    # the exported model is the best epoch's; the original file is kept beside it
    best = read_checkpoint(first / "checkpoints" / "epoch_000.ckpt")["state_dict"]
    net = trainers[1].lightning_module.net
    assert int(load_weights(net, first / "wasb.pth.tar")["meta"].get("epoch", -1)) == 0
    for k, v in net.state_dict().items():
        assert torch.equal(v, best[f"net.{k}"]), k
    assert (first / "wasb.pth.tar.bak").read_bytes() == original
    # said in one line
    said = [r.getMessage() for r in caplog.records if r.getMessage().startswith("resuming from")]
    assert len(said) == 1 and said[0].startswith(f"resuming from {first / 'checkpoints' / 'last.ckpt'}: continuing "
                                                 f"in {first}"), said


@pytest.mark.parametrize("how, reason", [
    ("resume_new_folder=true", "resume_new_folder=true"),
    ("paths.output_dir", "paths.output_dir is set"),
    ("hydra.run.dir", "hydra.run.dir is set"),
    ("debug=limit", "a debug run"),
    ("outside", "the checkpoint is not in a run's checkpoints/ folder"),
])
def test_an_explicit_folder_choice_keeps_a_new_folder_and_says_why(how, reason, tmp_path, caplog):
    from training.common import continue_run

    run, new = tmp_path / "runs" / "train" / "runs" / "old", tmp_path / "runs" / "train" / "runs" / "new"
    ckpt = (tmp_path / "elsewhere.ckpt") if how == "outside" else run / "checkpoints" / "last.ckpt"
    ckpt.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"epoch": 2, "global_step": 30, "state_dict": {}}, ckpt)
    extra = {"resume_new_folder=true": ["resume_new_folder=true"], "hydra.run.dir": [f"hydra.run.dir={new}"],
             "debug=limit": ["debug=limit"]}.get(how, [])
    cfg = compose_cfg(["+experiment=wasb_padel", f"ckpt_path={ckpt}", *extra], new)
    if how != "paths.output_dir":
        cfg = _as_cli(cfg, new)
    caplog.set_level(logging.INFO, logger="training.run")
    assert continue_run(cfg) is None
    assert Path(cfg.paths.output_dir) == new and cfg.ckpt_path == str(ckpt.resolve())
    said = [r.getMessage() for r in caplog.records if r.getMessage().startswith("resuming from")]
    assert said == [f"resuming from {ckpt.resolve()}: writing to the new run folder {new} ({reason})"]
    assert not (new / CONTINUED_NOTE).exists() and not (run / RESUMES_LOG).exists()


def test_continuing_backs_up_what_it_will_replace(tmp_path, caplog):
    """Resuming from another checkpoint than last.ckpt: last.ckpt, the exported model file and the results are
    copied to ``*.bak`` first (a second resume adds ``.bak2`` only when the files changed)."""
    from training.common import continue_run

    run, new = tmp_path / "runs" / "train" / "runs" / "old", tmp_path / "runs" / "train" / "runs" / "new"
    (run / "checkpoints").mkdir(parents=True)
    torch.save({"epoch": 2, "global_step": 30, "state_dict": {}}, run / "checkpoints" / "epoch_002.ckpt")
    torch.save({"epoch": 5, "global_step": 75, "state_dict": {}}, run / "checkpoints" / "last.ckpt")
    for name in ("wasb.pth.tar", "results.json", "results.csv"):
        (run / name).write_text(name)
    cfg = _as_cli(compose_cfg(["+experiment=wasb_padel", f"ckpt_path={run / 'checkpoints' / 'epoch_002.ckpt'}"], new),
                  new)
    caplog.set_level(logging.INFO, logger="training.run")
    assert continue_run(cfg) == run.resolve() and Path(cfg.paths.output_dir) == run.resolve()
    assert (run / "checkpoints" / "last.ckpt.bak").read_bytes() == (run / "checkpoints" / "last.ckpt").read_bytes()
    for name in ("wasb.pth.tar", "results.json", "results.csv"):
        assert (run / f"{name}.bak").read_text() == name
    assert "saved in epoch 3 at step 30" in (run / RESUMES_LOG).read_text()
    (run / "wasb.pth.tar").write_text("better")
    cfg = _as_cli(compose_cfg(["+experiment=wasb_padel", f"ckpt_path={run / 'checkpoints' / 'epoch_002.ckpt'}"], new),
                  new)
    continue_run(cfg)
    assert (run / "wasb.pth.tar.bak").read_text() == "wasb.pth.tar"
    assert (run / "wasb.pth.tar.bak2").read_text() == "better"
    assert not (run / "results.json.bak2").exists()


def test_a_hit_event_run_resumes_in_its_folder_too(tmp_path):
    """The hit-event tasks (training/events/run.py) build through training.common as detectors do: ``ckpt_path=last``
    continues in the first run's folder (checkpoints, CSV log, the exported model file with a ``.bak`` of the first)."""
    from inference.models.checkpoint import read_checkpoint
    from training.run import train

    logs = tmp_path / "runs"
    common = ["+experiment=hitnet_padel", "data.n_train=3", "data.n_val=2", "data.n_test=2", "data.batch_size=32",
              "trainer.accelerator=cpu", "trainer.limit_train_batches=1", f"data.cache_dir={tmp_path}/cache",
              "test=false", "progress_bar=false", f"paths.log_dir={logs}"]
    first, second = logs / "train" / "runs" / "first", logs / "train" / "runs" / "second"
    train(_as_cli(compose_cfg([*common, "trainer.max_epochs=1"], first), first))
    assert (first / "hitnet_padel.pth.tar").is_file()
    train(_as_cli(compose_cfg([*common, "trainer.max_epochs=2", "ckpt_path=last"], second), second))
    assert not (second / "checkpoints").exists() and not list(second.glob("*.pth.tar"))
    assert str(first) in (second / CONTINUED_NOTE).read_text()
    assert read_checkpoint(first / "checkpoints" / "last.ckpt")["epoch"] == 1
    assert [int(r["epoch"]) for r in _val_rows(first / "csv" / "version_0" / "metrics.csv")] == [0, 1]
    assert (first / "hitnet_padel.pth.tar.bak").is_file()
