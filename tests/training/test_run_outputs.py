"""What a run writes says what happened, once and in one numbering: progress lines in every mode (debug runs
too), one line per log record (Lightning's included), sweep folders where the docs say, results.json with
its config resolved, and no sync_dist advice for metrics that are already global."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import warnings

from omegaconf import OmegaConf
from training_fixtures import ROOT, compose_cfg, small_detector, tiny_padel  # noqa: F401  (fixtures)


def test_a_debug_run_logs_progress_lines_and_each_lightning_line_once(tiny_padel, tmp_path):
    """``train.py … debug=fdr > log.txt 2>&1`` (no terminal): the progress lines are there, and a Lightning
    INFO record appears once in the redirected output and once in train.log."""
    run = tmp_path / "run"
    overrides = [o for o in small_detector(tiny_padel, tmp_path / "cache") if "progress_log" not in o]
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    with (tmp_path / "log.txt").open("w") as f:
        out = subprocess.run([sys.executable, "train.py", "+experiment=wasb_padel", "debug=fdr", *overrides,
                              f"paths.log_dir={tmp_path / 'runs'}", f"hydra.run.dir={run}"], cwd=ROOT, env=env,
                             stdout=f, stderr=subprocess.STDOUT, timeout=900)
    text = (tmp_path / "log.txt").read_text()
    assert out.returncode == 0, text[-4000:]
    for where in (text, (run / "train.log").read_text()):
        assert sum("GPU available:" in ln for ln in where.splitlines()) == 1, where[-3000:]
        assert "training: 1 epochs, 1 steps per epoch" in where and "epoch 1/1 done after" in where


def test_debug_sweeps_write_where_the_docs_say(tmp_path):
    """``+hparams_search=detector_optuna … debug=limit`` (the docs' example) is a debug run: its sweep folder is
    runs/debug/multiruns/, and the docs and the sweep config say so beside the example."""
    def sweep_dir(*extra: str) -> str:
        cfg = compose_cfg(["+experiment=wasb_padel", "+hparams_search=detector_optuna", *extra,
                           f"paths.log_dir={tmp_path}"], tmp_path)
        return str(OmegaConf.select(cfg, "hydra.sweep.dir"))

    assert sweep_dir().startswith(f"{tmp_path}/train/multiruns/")
    assert sweep_dir("debug=limit").startswith(f"{tmp_path}/debug/multiruns/")
    docs = (ROOT / "docs" / "training.md").read_text().split("\n- ")
    example = [b for b in docs if "+hparams_search=detector_optuna hydra.sweeper.n_trials=4 debug=limit" in b]
    assert len(example) == 1 and "runs/debug/multiruns/" in example[0], example
    conf = (ROOT / "conf" / "hparams_search" / "detector_optuna.yaml").read_text()
    assert "debug=limit" in conf and "runs/debug/multiruns/" in conf


def test_results_json_holds_the_resolved_config(tmp_path, monkeypatch):
    from training.run import write_eval_results

    cfg = compose_cfg(["+experiment=wasb_padel", "ckpt_path=model.pth.tar"], tmp_path, name="eval")
    assert OmegaConf.to_container(cfg.data)["split_seed"] == "${seed}"
    path, _ = write_eval_results([{"model": "wasb", "f1": 0.5}], cfg)
    config = json.loads(path.read_text())["config"]
    assert config["data"]["split_seed"] == 1234 and config["paths"]["output_dir"] == str(tmp_path)
    assert "${" not in json.dumps({k: v for k, v in config.items() if k != "hydra"})
    # a value only Hydra's runtime (or a missing variable) could give is kept as written; the others resolve
    from training.results import resolved

    monkeypatch.delenv("RALLY3D_NOT_SET", raising=False)
    node = OmegaConf.create({"a": "${oc.env:RALLY3D_NOT_SET}", "b": {"c": "${seed}", "d": ["${seed}", 2]}, "seed": 3})
    assert resolved(node) == {"a": "${oc.env:RALLY3D_NOT_SET}", "b": {"c": 3, "d": [3, 2]}, "seed": 3}


def test_global_metrics_get_no_sync_dist_advice_in_a_process_group(tiny_padel, tmp_path):
    """In a process group (one gloo rank), the F1/TP/… metrics computed from all-reduced counts draw no "use
    sync_dist=True" warning; a metric that is not global still does."""
    import torch.distributed as dist
    from lightning.fabric.utilities.warnings import PossibleUserWarning
    from lightning.pytorch.trainer.connectors.logger_connector import result

    from training.run import train

    cfg = compose_cfg(["+experiment=wasb_padel", "debug=fdr",
                       *(o for o in small_detector(tiny_padel, tmp_path / "cache") if "progress_log" not in o)],
                      tmp_path / "run")
    result.warning_cache.clear()
    dist.init_process_group("gloo", init_method=f"file://{tmp_path / 'group'}", rank=0, world_size=1)
    try:
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            metrics = train(cfg)
            warnings.warn("It is recommended to use `self.log('val/mine', ..., sync_dist=True)` when logging on "
                          "epoch level in distributed setting", PossibleUserWarning)
    finally:
        dist.destroy_process_group()
    assert "val/f1" in metrics and "test/f1" in metrics
    # the losses are logged with sync_dist=True, which Lightning drops on one device (hence its advice here only)
    advice = [str(w.message) for w in seen if "sync_dist=True" in str(w.message) and "/loss'" not in str(w.message)]
    assert advice and all("'val/mine'" in a for a in advice), advice
