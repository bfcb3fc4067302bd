"""lightning-hydra-template conventions: the `debug=` group composes and wins over an experiment, the
loggers get the hyperparameters (hparams.yaml), train.py returns `optimized_metric` (the best epoch's, not
the last), the sweep configs compose with every choice, detectors export WASB-SBDT's `.pth.tar` layout,
`trainer=ddp_sim` composes, eval.yaml has no dead trainer/logger config."""
from __future__ import annotations

import os
from pathlib import Path

import pytest
from conftest import compose_cfg
import torch
import yaml
from omegaconf import OmegaConf

ROOT = Path(__file__).resolve().parents[2]
DEBUGS = sorted(p.stem for p in (ROOT / "conf" / "debug").glob("*.yaml"))


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    from synth.generate import SynthConfig, generate_dataset

    root = tmp_path_factory.mktemp("template") / "synth_padel"
    generate_dataset(root, 3, seed=5, config=SynthConfig(sport="padel", randomise_camera=False, width=320, height=192,
                                                         fps=30.0, codec="mp4v", randomise_look=False, max_frames=31))
    return root


def small(tiny: Path) -> list[str]:
    return [f"data.root={tiny}", "data.net_size=[64,112]", "data.crop=[32,32]", "data.batch_size=2",
            f"data.cache_dir={tiny.parent / 'cache'}", "trainer.accelerator=cpu"]


@pytest.mark.parametrize("debug", DEBUGS)
@pytest.mark.parametrize("experiment", ["wasb_padel", "hitnet_padel"])
def test_debug_configs_compose_and_win_over_the_experiment(debug, experiment, tmp_path):
    from training.run import apply_debug

    assert set(DEBUGS) == {"default", "fdr", "limit", "overfit", "profiler"}
    cfg = apply_debug(compose_cfg([f"+experiment={experiment}", f"debug={debug}"], tmp_path))
    assert cfg.task_name == "debug" and cfg.callbacks is None and cfg.logger is None
    assert cfg.trainer.accelerator == "cpu" and cfg.trainer.devices == 1
    expected_epochs = {"limit": 3, "overfit": 20}.get(debug, 1)
    assert cfg.trainer.max_epochs == expected_epochs          # the experiment's 30 / 10 are overridden
    if debug == "limit":
        assert cfg.trainer.limit_train_batches == 4              # hitnet_padel's 400 is overridden
    assert cfg.trainer.get("fast_dev_run") is (debug == "fdr")


def test_debug_fdr_runs_one_step(tiny, tmp_path):
    from training.run import train

    cfg = compose_cfg(["+experiment=wasb_padel", "debug=fdr", *small(tiny)], tmp_path)
    metrics = train(cfg)
    assert torch.isfinite(torch.tensor(metrics["train/loss_step"]))
    assert "val/f1" in metrics and "test/f1" in metrics
    assert not list(tmp_path.glob("**/*.ckpt"))                    # fast_dev_run saves nothing


def test_trainer_ddp_sim_composes(tmp_path):
    import hydra

    cfg = compose_cfg(["+experiment=wasb_padel", "trainer=ddp_sim"], tmp_path)
    assert cfg.trainer.devices == 2 and cfg.trainer.accelerator == "cpu"
    strategy = hydra.utils.instantiate(cfg.trainer.strategy)
    assert strategy.process_group_backend == "gloo"


def test_optimized_metric_is_the_best_epoch_and_hparams_reach_the_logger(tiny, tmp_path):
    """Three epochs: train.py's value is the maximum of the logged val/f1 (best-vs-last in the test
    below); hparams.yaml holds the composed config and the modules' own hyperparameters."""
    import csv

    from training.run import optimized_metric, train

    cfg = compose_cfg(["+experiment=wasb_padel", *small(tiny), "trainer.max_epochs=3", "trainer.limit_train_batches=2",
                       "trainer.limit_val_batches=2", "test=false"], tmp_path)
    metrics = train(cfg)
    value = optimized_metric(cfg, metrics)
    with next(tmp_path.glob("csv/version_*/metrics.csv")).open() as f:
        f1s = [float(r["val/f1"]) for r in csv.DictReader(f) if r.get("val/f1")]
    assert len(f1s) == 3 and value == pytest.approx(max(f1s))
    assert metrics["val/f1"] == pytest.approx(f1s[-1])
    hp = yaml.safe_load(next(tmp_path.glob("csv/version_*/hparams.yaml")).read_text())
    assert hp["model"]["net"]["name"] == "wasb" and hp["data"]["root"] == str(tiny)
    assert hp["optimized_metric"] == "val/f1_best" and hp["seed"] == 1234
    assert hp["model/params/non_trainable"] > 0                     # the 39 frozen unused tensors
    assert hp["tau_px"] == 4.0 and hp["net_size"] == [64, 112]      # the module's and data module's own


def test_val_f1_best_is_the_maximum_not_the_last_epoch():
    """Three validation epochs with F1 rising then falling: val/f1_best is the second epoch's; the
    sanity check's validation does not count."""
    from functools import partial
    from types import SimpleNamespace

    import numpy as np

    from inference.models.registry import build_model
    from training.detection.losses import HeatmapLoss
    from training.detection.module import BallDetector

    det = BallDetector(build_model("tracknetv2"), HeatmapLoss("wbce"), partial(torch.optim.Adam, lr=1e-3))
    logged: dict[str, float] = {}
    det.log = lambda name, value, **kw: logged.__setitem__(name, value)
    gt = np.zeros((10, 2))
    vis = np.ones(10, int)
    f1s = []
    for sanity, hits in ((True, 10), (False, 4), (False, 8), (False, 6)):
        det.trainer = SimpleNamespace(sanity_checking=sanity)
        seen = np.arange(10) < hits                                  # hits TP, the rest FN
        det.outputs["val"] = [(seen, np.where(seen[:, None], gt, np.nan), seen * 1.0, vis, gt)]
        det.on_validation_epoch_end()
        f1s.append(logged["val/f1"])
    assert f1s[0] == 1.0 and f1s[1:] == pytest.approx([2 * .4 / 1.4, 2 * .8 / 1.8, 2 * .6 / 1.6])
    assert logged["val/f1_best"] == pytest.approx(f1s[2]) and logged["val/f1"] == pytest.approx(f1s[3])
    state: dict = {}
    det.on_save_checkpoint(state)
    resumed = BallDetector(build_model("tracknetv2"), HeatmapLoss("wbce"), partial(torch.optim.Adam, lr=1e-3))
    resumed.on_load_checkpoint(state)
    assert resumed.best["val/f1"] == pytest.approx(f1s[2])          # a resumed run keeps its best


def test_optimized_metric_missing_is_named(tmp_path):
    from training.run import optimized_metric

    cfg = compose_cfg(["+experiment=wasb_padel", "optimized_metric=val/nothing"], tmp_path)
    assert optimized_metric(cfg, {"val/f1": 0.5}) is None           # a single run: warned, not fatal
    cfg = compose_cfg(["+experiment=hitnet_padel"], tmp_path)
    assert cfg.optimized_metric == "events/val_f1"
    assert optimized_metric(cfg, {"events/val_f1": 0.25, "val/f1": 0.9}) == 0.25


@pytest.mark.parametrize("search,experiment", [("detector_optuna", "wasb_padel"), ("hitnet_grid", "hitnet_padel"),
                                               ("hitnet_optuna", "hitnet_padel")])
def test_sweep_configs_compose_with_every_choice(search, experiment, tmp_path):
    """Every value a sweeper may pick is a valid override of the experiment (a typo fails here, not
    in trial 7 of a night's sweep)."""
    cfg = compose_cfg([f"+experiment={experiment}", f"+hparams_search={search}"], tmp_path)
    assert cfg.optimized_metric == ("val/f1_best" if experiment.startswith("wasb") else "events/val_f1")
    params = cfg.hydra.sweeper.params
    assert params
    for key, spec in params.items():
        spec = str(spec)
        if spec.startswith("choice("):
            values = [v.strip() for v in spec[len("choice("):-1].split(",")]
        elif "interval(" in spec:
            lo, hi = spec[spec.index("interval(") + 9:].rstrip(")").split(",")[:2]
            values = [lo.strip(), hi.strip().rstrip(")")]
        else:
            values = [v.strip() for v in spec.split(",")]
        for v in values:
            one = compose_cfg([f"+experiment={experiment}", f"{key}={v}"], tmp_path)
            if (ROOT / "conf" / key).is_dir():                      # a config group (loss=focal)
                assert one.model.loss.kind == v
            else:
                assert OmegaConf.select(one, key) == pytest.approx(float(v))


def test_detector_export_is_wasb_sbdt_layout(tmp_path):
    """What WASB-SBDT's own loader does with a ``*_best.pth.tar``: ``torch.load`` then
    ``model.load_state_dict(ckpt['model_state_dict'])`` on the bare network, with ``epoch``,
    ``train_loss`` and ``test_*`` beside it."""
    from functools import partial

    from inference.models.checkpoint import read_checkpoint
    from inference.models.registry import build_model
    from training.detection.losses import HeatmapLoss
    from training.detection.module import BallDetector
    from training.run import export_detector

    torch.manual_seed(0)
    module = BallDetector(build_model("wasb"), HeatmapLoss("wbce"), partial(torch.optim.Adam, lr=1e-3))
    cfg = compose_cfg(["+experiment=wasb_padel", f"export_path={tmp_path / 'mine_best.pth.tar'}"], tmp_path)
    metrics = {"train/loss_epoch": 0.12, "val/f1": 0.8, "val/f1_best": 0.85, "test/f1": 0.75, "test/tp": 30.0,
               "lr-Adam": 1e-3}
    outs = export_detector(module, "", cfg, metrics)
    assert [p.name for p in outs] == ["wasb.pth.tar", "mine_best.pth.tar"]
    ckpt = torch.load(outs[1], map_location="cpu", weights_only=True)
    assert {"model_state_dict", "epoch", "train_loss", "test_f1", "val_f1_best"} <= set(ckpt)
    assert ckpt["train_loss"] == pytest.approx(0.12) and ckpt["test_f1"] == pytest.approx(0.75)
    bare = build_model("wasb")
    bare.load_state_dict(ckpt["model_state_dict"])                   # strict, no prefixes
    assert all(torch.equal(bare.state_dict()[k], v) for k, v in module.net.state_dict().items())
    assert read_checkpoint(outs[0])["epoch"] == 0


def test_eval_config_has_no_dead_logger_and_reads_the_accelerator(tmp_path):
    from training.run import eval_device

    cfg = compose_cfg(["+experiment=wasb_padel", "trainer.accelerator=cpu"], tmp_path, name="eval")
    assert "logger" not in cfg
    assert eval_device(cfg) == "cpu"
    if not torch.cuda.is_available():
        cfg = compose_cfg(["+experiment=wasb_padel", "trainer.accelerator=gpu"], tmp_path, name="eval")
        with pytest.raises(ValueError, match="trainer.accelerator=cpu"):
            eval_device(cfg)
    assert cfg.results_path is None                                      # results.{json,csv} in the run folder


@pytest.mark.slow
def test_detector_optuna_sweep_runs_two_trials(tiny, tmp_path):
    """``train.py -m +hparams_search=detector_optuna`` as a user runs it (two trials of ``debug=fdr``):
    Optuna receives each trial's val/f1_best and writes its best parameters."""
    import subprocess
    import sys

    env = {**os.environ, "PROJECT_ROOT": str(ROOT), "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, str(ROOT / "train.py"), "+experiment=wasb_padel", "+hparams_search=detector_optuna",
           "hydra.sweeper.n_trials=2", "hydra.sweeper.sampler.n_startup_trials=2", "debug=fdr",
           f"paths.log_dir={tmp_path}", *small(tiny)]
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1500)
    assert out.returncode == 0, out.stderr[-4000:]
    results = list(tmp_path.glob("debug/multiruns/*/optimization_results.yaml"))
    assert len(results) == 1, out.stdout[-2000:]
    best = yaml.safe_load(results[0].read_text())
    assert set(best["best_params"]) == {"model.optimizer.lr", "loss", "data.radius"}
    assert 0.0 <= float(best["best_value"]) <= 1.0
    assert len(list(results[0].parent.glob("[0-9]*/.hydra/overrides.yaml"))) == 2
