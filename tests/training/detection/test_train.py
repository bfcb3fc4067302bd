"""Every experiment composes and runs one fast_dev_run step on CPU on a tiny generated dataset; resume
and pretrained fine-tuning work; bad data gives clear errors."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from conftest import compose_cfg
import torch

from training.run import evaluate, train
from synth.generate import SynthConfig, generate_dataset

ROOT = Path(__file__).resolve().parents[3]
EVENT_MODELS = ("hitnet", "tagger")  # the hit-event experiments run in tests/training/events/test_hitnet_train.py
EXPERIMENTS = sorted(p.stem for p in (ROOT / "conf" / "experiment").glob("*.yaml") if not p.stem.startswith(EVENT_MODELS))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """Three short synthetic clips per sport (a train, a val and a test split)."""
    root = tmp_path_factory.mktemp("ballsets")
    for sport in ("padel", "tennis"):
        generate_dataset(root / f"synth_{sport}", 3, seed=5, config=SynthConfig(
            sport=sport, randomise_camera=False, width=320, height=192, fps=30.0, codec="mp4v",
            randomise_look=False, max_frames=40))
    return root


def small(tiny: Path, sport: str) -> list[str]:
    return [f"data.root={tiny}/synth_{sport}", "data.net_size=[64,112]", "data.crop=[32,32]", "data.batch_size=2",
            "trainer.accelerator=cpu", f"data.cache_dir={tiny}/.cache"]


@pytest.mark.parametrize("experiment", EXPERIMENTS)
def test_experiment_fast_dev_run(experiment, tiny, tmp_path):
    sport = experiment.split("_")[1]  # wasb_padel, wasb_padel_finetune
    cfg = compose_cfg([f"+experiment={experiment}", "trainer.fast_dev_run=true", *small(tiny, sport)], tmp_path)
    assert cfg.model.net.name == experiment.split("_")[0]
    metrics = train(cfg)
    assert "train/loss" in metrics or "train/loss_step" in metrics
    assert torch.isfinite(torch.tensor(metrics.get("train/loss", metrics.get("train/loss_step"))))


def test_train_checkpoint_resume_and_eval(tiny, tmp_path):
    base = ["+experiment=wasb_padel", "trainer.max_epochs=1", "trainer.limit_train_batches=2",
            "trainer.limit_val_batches=1", "trainer.limit_test_batches=1", *small(tiny, "padel")]
    cfg = compose_cfg(base, tmp_path)
    metrics = train(cfg)
    assert "val/f1" in metrics and "test/f1" in metrics
    last = tmp_path / "checkpoints" / "last.ckpt"
    assert last.is_file()
    resumed = compose_cfg([*base, "trainer.max_epochs=2", f"ckpt_path={last}", "test=false"], tmp_path / "r")
    train(resumed)
    state = torch.load(tmp_path / "r" / "checkpoints" / "last.ckpt", map_location="cpu", weights_only=False)
    assert state["epoch"] == 1
    ev = compose_cfg(["+experiment=wasb_padel", f"ckpt_path={last}", *small(tiny, "padel")], tmp_path / "e",
                     name="eval")
    scores = evaluate(ev)
    assert {"f1_tau4_tracker", "f1_tau10_tracker", "f1_tau10_max-score"} <= set(scores)


def test_pretrained_public_checkpoint_fine_tunes(tiny, tmp_path):
    from inference.models.checkpoint import save_wasb_checkpoint
    from inference.models.registry import build_model

    path = tmp_path / "wasb_tennis_best.pth.tar"
    save_wasb_checkpoint(build_model("wasb"), path)
    cfg = compose_cfg(["+experiment=wasb_padel", "trainer.fast_dev_run=true", f"model.pretrained={path}",
                       *small(tiny, "padel")], tmp_path)
    train(cfg)


def test_missing_dataset_is_a_clear_error(tmp_path):
    cfg = compose_cfg(["+experiment=wasb_padel", "trainer.fast_dev_run=true", f"data.root={tmp_path}/nothing"],
                      tmp_path)
    with pytest.raises(SystemExit, match=r"no dataset at .*nothing.*data.root=DIR.*rally3d synth --sport padel"):
        train(cfg)


def test_eval_needs_a_checkpoint(tmp_path):
    """Said before any data is looked at: the default dataset (missing on a fresh clone) is not generated
    first (that took ~4 minutes before the error came)."""
    data = tmp_path / "data"
    cfg = compose_cfg(["+experiment=wasb_padel", f"paths.data_dir={data}"], tmp_path, name="eval")
    with pytest.raises(ValueError, match="ckpt_path"):
        evaluate(cfg)
    with pytest.raises(FileNotFoundError, match="not found"):
        evaluate(compose_cfg(["+experiment=wasb_padel", f"paths.data_dir={data}", f"ckpt_path={tmp_path / 'x.pt'}"],
                             tmp_path, name="eval"))
    assert not data.exists()


def test_plus_experiment_spelling_from_the_command_line(tiny, tmp_path):
    """`python train.py +experiment=wasb_padel` composes (Hydra pitfall: with `experiment: null` in train.yaml's
    defaults only `experiment=...` works and `+experiment=...` fails, and the other way round without it)."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, str(ROOT / "train.py"), "+experiment=wasb_padel", "--cfg", "job",
                          "--resolve"], capture_output=True, text=True, env={**os.environ, "PROJECT_ROOT": str(ROOT)})
    assert out.returncode == 0, out.stderr[-2000:]
    assert "name: wasb" in out.stdout and "synth_padel" in out.stdout


def test_clip_without_ball_csv_and_short_video_are_clear_errors(tiny, tmp_path):
    import shutil

    from inference.clipio import Clip, FormatError
    from training.detection.data import load_clip

    src = tiny / "synth_padel" / "clip_0000"
    no_ball = tmp_path / "no_ball"
    shutil.copytree(src, no_ball)
    (no_ball / "ball.csv").unlink()
    with pytest.raises(FormatError, match="ball.csv.*file not found"):
        load_clip(Clip(no_ball), (64, 112), tmp_path / "cache")
    short = tmp_path / "short"
    shutil.copytree(src, short)
    text = (short / "clip.yaml").read_text().replace("n_frames: 40", "n_frames: 55")
    (short / "clip.yaml").write_text(text)
    with pytest.raises(FormatError, match="video has 40 frames"):
        load_clip(Clip(short), (64, 112), tmp_path / "cache")


def test_targets_disks_and_soft_maps():
    import numpy as np

    from training.detection.data import disk_heatmaps, soft_heatmaps

    centres = np.array([[10.0, 8.0], [np.nan, np.nan]])
    disk = disk_heatmaps(centres, (20, 30), 2.5)
    assert disk[0].sum() == 21 and disk[1].sum() == 0           # WASB's 21-pixel disk
    soft = soft_heatmaps(centres[:1], (20, 30), 2.5)[0]
    assert soft[8, 10] == 1.0 and 0 < soft[soft > 0].min() < 1.0 and soft.sum() < disk[0].sum() + 1


def test_compare_puts_several_models_in_one_table(tiny, tmp_path):
    from inference.models.checkpoint import save_wasb_checkpoint
    from inference.models.registry import build_model
    from training.detection import compare

    ckpts = {}
    for name in ("wasb", "monotrack"):
        torch.manual_seed(0)
        ckpts[f"{name}_padel"] = save_wasb_checkpoint(build_model(name), tmp_path / f"{name}.pth.tar")
    out = tmp_path / "table.md"
    args = [f"{tiny}/synth_padel", *(f"{k}={v}" for k, v in ckpts.items()), "--set", "data.net_size=[64,112]",
            "--set", f"data.cache_dir={tiny}/.cache", "--out", str(out)]
    assert compare.main(args) == 0
    text = out.read_text()
    assert "python -m training.detection.compare" in text
    assert text.count("τ = ") == 2  # τ = 4 px original and τ = 10 px at 1280×720
    for row in ("wasb + tracker", "wasb + max-score", "monotrack + tracker", "monotrack + max-score"):
        assert text.count(f"| {row} |") == 2
    with pytest.raises(SystemExit, match="unknown experiment 'yolo_padel'"):
        compare.main([f"{tiny}/synth_padel", f"yolo_padel={ckpts['wasb_padel']}"])
    with pytest.raises(SystemExit, match="checkpoint .*missing.pth not found"):
        compare.main([f"{tiny}/synth_padel", f"wasb_padel={tmp_path / 'missing.pth'}"])


def test_channels_last_and_compile_keep_outputs_and_state_dict_names():
    from functools import partial

    from inference.models.registry import build_model
    from training.detection.losses import HeatmapLoss
    from training.detection.module import BallDetector

    torch.manual_seed(0)
    net = build_model("wasb").eval()
    plain_names = list(net.state_dict())
    x = torch.randn(1, 9, 64, 96)
    with torch.no_grad():
        expected = net(x)
    make = partial(BallDetector, loss=HeatmapLoss("wbce"), optimizer=partial(torch.optim.Adam, lr=1e-3))
    fast = make(net=net, channels_last=True).eval()
    with torch.no_grad():
        got = fast(x)
    assert torch.allclose(got, expected, atol=1e-4)
    convs = [p for p in fast.net.parameters() if p.ndim == 4]
    assert all(p.is_contiguous(memory_format=torch.channels_last) for p in convs)
    assert any(not p.is_contiguous() for p in convs)  # really NHWC, not only 1×1 kernels
    assert [k.removeprefix("net.") for k in fast.state_dict() if k.startswith("net.")] == plain_names
    compiled = make(net=build_model("wasb"), compile=True)
    assert [k.removeprefix("net.") for k in compiled.state_dict() if k.startswith("net.")] == plain_names
