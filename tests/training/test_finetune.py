"""Fine-tuning is the small-data default: every experiment takes ``init_weights=`` (no ``+``), the
``*_finetune`` experiments start from the shipped weights with the stem frozen, and a file whose input
normalisation differs from the data's is refused with the config key to change."""
from __future__ import annotations

from pathlib import Path

import pytest
import torch
from training_fixtures import ROOT, compose_cfg, labeler_clips, small_detector  # noqa: F401  (fixtures)

from inference.models.checkpoint import META_KEY, load_weights, read_checkpoint
from inference.models.registry import build_model

EXPERIMENTS = sorted(p.stem for p in (ROOT / "conf" / "experiment").glob("*.yaml"))
SHIPPED = ROOT / "inference" / "weights"


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_every_experiment_takes_init_weights(experiment, tmp_path):
    cfg = compose_cfg([f"+experiment={experiment}", "init_weights=/some/model.pth.tar"], tmp_path)
    assert cfg.init_weights == "/some/model.pth.tar"
    if experiment.endswith("_finetune"):  # the shipped weights by default, and they exist
        default = compose_cfg([f"+experiment={experiment}"], tmp_path).init_weights
        assert Path(default).parent == SHIPPED and Path(default).is_file()


def test_wasb_finetune_starts_from_the_shipped_weights_with_the_stem_frozen(labeler_clips, tmp_path):
    from training.run import train

    cfg = compose_cfg(["+experiment=wasb_padel_finetune", "trainer.max_epochs=1", "trainer.limit_train_batches=3",
                       "trainer.limit_val_batches=1", "test=false", "model.optimizer.lr=1e-2",
                       *small_detector(labeler_clips, tmp_path / "cache")], tmp_path / "run")
    train(cfg)
    shipped = build_model("wasb", frames_in=3, frames_out=3)
    load_weights(shipped, SHIPPED / "wasb_padel.pth.tar")
    tuned = build_model("wasb", frames_in=3, frames_out=3)
    info = load_weights(tuned, tmp_path / "run" / "wasb.pth.tar")
    assert info["input"].normalize == "imagenet"
    before, after = shipped.state_dict(), tuned.state_dict()
    stem = [k for k in before if k.split(".")[0] in ("conv1", "bn1", "conv2", "bn2", "layer1")]
    assert stem and all(torch.equal(before[k], after[k]) for k in stem)  # weights and BN statistics kept
    moved = [k for k in before if k not in stem and before[k].is_floating_point()
             and not torch.equal(before[k], after[k])]
    assert len(moved) > len(before) // 4  # the rest learned, from the shipped values (not from scratch)
    close = [k for k in moved if k.endswith(".weight")
             and (after[k] - before[k]).norm() < 0.5 * before[k].norm()]
    assert len(close) > len(moved) // 4


def test_init_weights_with_another_normalisation_is_refused_naming_the_key(labeler_clips, tmp_path):
    from training.run import build, init_source

    cfg = compose_cfg(["+experiment=wasb_padel_finetune", "data.normalize=unit",
                       *small_detector(labeler_clips, tmp_path / "cache")], tmp_path / "run")
    assert init_source(cfg) == str(SHIPPED / "wasb_padel.pth.tar")
    with pytest.raises(ValueError, match=r"imagenet input normalisation but data.normalize=unit: fine-tune with "
                                         r"data.normalize=imagenet"):
        build(cfg)
    assert read_checkpoint(SHIPPED / "wasb_padel.pth.tar").get(META_KEY, {}).get("normalize") in (None, "imagenet")


class _CreatesFile:
    """Unpickling this object calls ``open(marker, "w")``: it creates a file on disk."""

    def __init__(self, marker: Path):
        self.marker = str(marker)

    def __reduce__(self):
        import builtins

        return builtins.open, (self.marker, "w")


@pytest.mark.parametrize("how", ["init_weights", "model.pretrained", "ckpt_path", "eval ckpt_path", "events"])
def test_training_never_unpickles_a_checkpoint_without_trust(how, labeler_clips, tmp_path):
    """train.py / eval.py refuse a file holding pickled objects (the payload would create a file) unless
    trust_checkpoint=true; the error names the opt-in."""
    from inference.models import UntrustedCheckpointError
    from training.run import build, evaluate, resume_path

    marker = tmp_path / "pwned.txt"
    evil = tmp_path / "evil.pth.tar"
    torch.save({"model_state_dict": build_model("wasb").state_dict(), "payload": _CreatesFile(marker)}, evil)
    det = ["+experiment=wasb_padel", *small_detector(labeler_clips, tmp_path / "cache")]
    if how == "events":  # hit-event model files are read with the allow-list only (no opt-in exists)
        from training.events.run import init_events

        with pytest.raises(ValueError, match="not a readable rally3d hit-event model"):
            init_events(None, evil)
    else:
        with pytest.raises(UntrustedCheckpointError, match="trust_checkpoint=true"):
            if how in ("init_weights", "model.pretrained"):
                build(compose_cfg([*det, f"{how}={evil}"], tmp_path / "run"))
            elif how == "ckpt_path":
                resume_path(compose_cfg([*det, f"ckpt_path={evil}"], tmp_path / "run"))
            else:
                ev = [o for o in det if "progress_log" not in o]  # eval has no callbacks
                evaluate(compose_cfg([*ev, f"ckpt_path={evil}"], tmp_path / "eval", name="eval"))
    assert not marker.exists()
