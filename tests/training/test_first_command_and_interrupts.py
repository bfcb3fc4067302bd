"""The first command on a fresh clone and a run that is stopped never lose time or work:

- ``python train.py +experiment=wasb_padel`` without its dataset stops with one line naming the exact
  ``rally3d synth`` command, before torch or Lightning are imported (or makes the dataset, printing progress
  lines a log file can show);
- SIGTERM (``kill PID``, a cluster's pre-emption) and Ctrl-C (SIGINT) mid-epoch leave a ``last.ckpt`` of
  the step reached, and ``ckpt_path=last`` resumes from it;
- ProgressLog's lines say the step, loss, speed and time left.
"""
from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import wait_until
from training_fixtures import ROOT, compose_cfg, small_detector, tiny_padel  # noqa: F401  (fixtures)

from inference.models.checkpoint import read_checkpoint
from training.preflight import DEFAULT_DATASETS, check_data, generate_default, synth_command


def _train_cmd(*overrides: str) -> list[str]:
    return [sys.executable, "train.py", *overrides]


def _env() -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}


def test_first_command_without_data_names_the_command_before_importing_torch(tmp_path):
    out = subprocess.run([sys.executable, "-X", "importtime", *_train_cmd(
        "+experiment=wasb_padel", f"paths.data_dir={tmp_path}/data", f"paths.log_dir={tmp_path}/runs",
        "auto_data=false")[1:]], cwd=ROOT, env=_env(), capture_output=True, text=True, timeout=120)
    assert out.returncode == 1
    said = [ln for ln in out.stderr.splitlines() if not ln.startswith("import time:")]
    expected = synth_command(f"{tmp_path}/data/synth_padel", DEFAULT_DATASETS["synth_padel"])
    assert len(said) == 1 and f"`{expected}`" in said[0] and "Traceback" not in out.stderr, out.stderr[-2000:]
    imported = {ln.rsplit("|", 1)[-1].strip() for ln in out.stderr.splitlines() if ln.startswith("import time:")}
    assert imported and not imported & {"torch", "lightning", "cv2"}  # stopped before anything heavy
    assert not (tmp_path / "runs").exists() or not list((tmp_path / "runs").rglob("*.ckpt"))


def test_first_command_makes_the_default_dataset_when_allowed(tmp_path):
    cfg = compose_cfg(["+experiment=wasb_padel", f"paths.data_dir={tmp_path}/data"], tmp_path / "run")
    calls = []
    made = check_data(cfg, generate=lambda root, spec: calls.append((root, spec)))
    assert made == [f"{tmp_path}/data/synth_padel"] and calls == [(made[0], DEFAULT_DATASETS["synth_padel"])]
    # a folder that is not a default dataset is never generated: one line naming data.root and the fix
    cfg = compose_cfg(["+experiment=wasb_padel", f"data.root={tmp_path}/my_clips"], tmp_path / "run")
    with pytest.raises(SystemExit, match=r"no dataset at .*my_clips .*pass data.root=DIR"):
        check_data(cfg, generate=lambda root, spec: pytest.fail("must not generate"))


def test_default_dataset_generation_prints_progress_lines_to_a_log(tmp_path, capsys):
    spec = {"sport": "padel", "clips": 4, "seed": 3, "max_frames": 12,
            "config": {"randomise_camera": False, "width": 160, "height": 96, "codec": "mp4v",
                       "randomise_look": False}}
    generate_default(tmp_path / "synth_padel", spec)
    text = capsys.readouterr().out  # not a terminal: lines, not a bar
    assert "generating the default dataset now — 4 padel clips" in text and "rally3d synth --sport padel" in text
    assert re.search(r"^  4/4 clips, \d+ frames, \d+ s$", text, re.M)
    assert (tmp_path / "synth_padel" / "manifest.yaml").is_file()


def _step_of(ckpt: Path) -> int:
    return int(read_checkpoint(ckpt)["global_step"])  # the allow-list reads what SafeCheckpoint writes


def _stop_after(cmd: list[str], log: Path, steps: int, sig: int) -> subprocess.CompletedProcess:
    """Run ``cmd`` (output to ``log``), send ``sig`` once ProgressLog has logged ``steps`` steps."""
    with log.open("w") as f:
        proc = subprocess.Popen(cmd, cwd=ROOT, env=_env(), stdout=f, stderr=subprocess.STDOUT,  # Ctrl-C reaches it
                                preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # even in `make test &`
        try:
            wait_until(lambda: proc.poll() is not None or re.search(rf"step {steps}/", log.read_text()),
                       what=f"step {steps} in {log}")
            assert proc.poll() is None, log.read_text()[-3000:]
            proc.send_signal(sig)
            proc.wait(timeout=300)
        finally:
            if proc.poll() is None:
                proc.kill()
    return proc


def test_sigterm_and_ctrl_c_keep_the_step_reached_and_last_resumes(tiny_padel, tmp_path):
    logs = tmp_path / "logs"
    common = ["+experiment=wasb_padel", *small_detector(tiny_padel, tmp_path / "cache"), "data.crop=[32,32]",
              f"paths.log_dir={logs}", "trainer.max_epochs=1", "trainer.limit_train_batches=400",
              "trainer.limit_val_batches=1", "test=false", "progress_bar=false",
              "callbacks.last_checkpoint.every_n_minutes=null"]
    run1 = logs / "train" / "runs" / "first"
    proc = _stop_after(_train_cmd(*common, f"hydra.run.dir={run1}"), tmp_path / "first.log", 3, signal.SIGTERM)
    text = (tmp_path / "first.log").read_text()
    ckpt1 = run1 / "checkpoints" / "last.ckpt"
    assert proc.returncode != 0 and ckpt1.is_file(), text[-3000:]
    assert "resume with ckpt_path=" in text
    step1 = _step_of(ckpt1)
    assert 3 <= step1 < 400  # the step reached, not an epoch boundary
    assert not list(run1.glob("checkpoints/.*.tmp"))

    run2 = logs / "train" / "runs" / "second"
    proc = _stop_after(_train_cmd(*common, "ckpt_path=last", f"hydra.run.dir={run2}"), tmp_path / "second.log",
                       step1 + 2, signal.SIGINT)
    text = (tmp_path / "second.log").read_text()
    assert f"resuming from {ckpt1}" in text, text[-3000:]
    step2 = _step_of(run2 / "checkpoints" / "last.ckpt")
    assert step2 >= step1 + 2  # continued from the first run's step (a fresh start would be at ~2)


def test_progress_lines_say_step_loss_speed_and_eta(tiny_padel, tmp_path, monkeypatch):
    import training.run as run
    from training.callbacks import ProgressLog

    cfg = compose_cfg(["+experiment=wasb_padel", "trainer.max_epochs=2", "trainer.limit_train_batches=3",
                       "trainer.limit_val_batches=1", "test=false", "callbacks.progress_log.every_n_steps=2",
                       *(o for o in small_detector(tiny_padel, tmp_path / "cache") if "progress_log" not in o)],
                      tmp_path / "run")
    seen: list[ProgressLog] = []
    build = run.build

    def spy(c):
        dm, model, trainer = build(c)
        seen.extend(cb for cb in trainer.callbacks if isinstance(cb, ProgressLog))
        return dm, model, trainer

    monkeypatch.setattr(run, "build", spy)
    run.train(cfg)
    lines = seen[0].lines
    assert lines[0].startswith("training: 2 epochs, 3 steps per epoch, 6 steps in all")
    step = [ln for ln in lines if ln.startswith("epoch ") and "· step" in ln]
    assert [ln.split(" · ")[1] for ln in step] == ["step 2/3 (total 2/6)", "step 2/3 (total 5/6)"]
    assert all(re.search(r"loss [\d.e+-]+ \(mean [\d.e+-]+\) · [\d.]+ s/step, [\d.]+ samples/s · ETA epoch "
                         r"\d+m\d\ds, run \d+m\d\ds", ln) for ln in step), step
    assert sum(ln.startswith("epoch ") and " done after " in ln for ln in lines) == 2
    assert (tmp_path / "run" / "checkpoints" / "last.ckpt").is_file()  # every epoch end, validation or not


def test_an_exception_mid_epoch_leaves_last_ckpt_at_the_step_reached(tiny_padel, tmp_path, monkeypatch, caplog):
    """… and says so counting epochs as the progress lines do (from 1)."""
    import lightning as L

    import training.run as run

    class Boom(L.Callback):
        def on_train_batch_end(self, trainer, *args):
            if trainer.global_step == 3:
                raise RuntimeError("disk full (injected)")

    build = run.build

    def with_boom(c):
        dm, model, trainer = build(c)
        trainer.callbacks.append(Boom())
        return dm, model, trainer

    monkeypatch.setattr(run, "build", with_boom)
    cfg = compose_cfg(["+experiment=wasb_padel", "trainer.max_epochs=2", "trainer.limit_train_batches=50",
                       "trainer.limit_val_batches=1", "test=false", "callbacks.last_checkpoint.every_n_minutes=null",
                       *small_detector(tiny_padel, tmp_path / "cache")], tmp_path / "run")
    with caplog.at_level("INFO", logger="training.callbacks"), pytest.raises(RuntimeError, match="injected"):
        run.train(cfg)
    assert _step_of(tmp_path / "run" / "checkpoints" / "last.ckpt") == 3
    said = [r.getMessage() for r in caplog.records if r.name == "training.callbacks"]
    assert any(m.startswith("epoch 1/2 · step 3/") for m in said), said
    assert any(m.startswith("RuntimeError at epoch 1/2, step 3: saved ") for m in said), said
