"""Multi-process training: global metrics over DDP ranks, unpadded evaluation shards, frozen unused
parameters, private cache temp names, and (slow) `trainer=ddp_sim` runs of train.py whose global val/f1
equals a single-process validation of the same weights on the same data."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import torch

from training.distributed import EvalShard, eval_sampler

ROOT = Path(__file__).resolve().parents[2]


def free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# ------------------------------------------------------------------------------ a 2-rank gloo group
RANK_SCRIPT = textwrap.dedent('''
    import json, sys
    from functools import partial
    import numpy as np, torch
    rank, port, data = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    torch.distributed.init_process_group("gloo", init_method=f"tcp://127.0.0.1:{port}", rank=rank, world_size=2)
    z = np.load(data)
    shard = slice(rank, None, 2)                 # what each rank validates: half of the frames, uneven
    from inference.models.registry import build_model
    from training.detection.losses import HeatmapLoss
    from training.detection.module import BallDetector
    det = BallDetector(build_model("tracknetv2"), HeatmapLoss("wbce"), partial(torch.optim.Adam, lr=1e-3),
                       tau_px=10.0, ignore_flags=[3])
    det.outputs["val"] = [(z["pred_vis"][shard], z["pred_xy"][shard], z["score"][shard], z["vis"][shard],
                           z["gt"][shard])]
    report = det.report("val").as_dict()
    from training.events.models.hitnet import log_event_metrics
    class Fake:                                   # what log_event_metrics needs of a LightningModule
        logged = {}
        trainer = type("T", (), {"sanity_checking": False})()
        def log(self, name, value, **kw): self.logged[name] = value
    fake = Fake()
    outputs = [(torch.as_tensor(z["ev_pred"][shard]), torch.as_tensor(z["ev_y"][shard]))] if rank == 0 or len(z["ev_y"]) > 1 else []
    log_event_metrics(fake, "val", outputs, 4)
    print("RESULT " + json.dumps({"report": report, "events": fake.logged}), flush=True)
    torch.distributed.barrier()                   # both ranks are done with the group
    import os
    os._exit(0)  # no gloo teardown: a rank closing its sockets while the other tears down can abort (SIGABRT)
''')


def test_counts_all_reduced_over_two_gloo_ranks_equal_single_process(tmp_path):
    """Two real processes in a gloo group, each with half of the frames: the detector report (F1, counts,
    RMSE, AP) and the hit-event F1 are the single-process figures of all frames, on both ranks."""
    from inference.detection.metrics import evaluate_detections
    from training.events.models.hitnet import macro_event_f1

    rng = np.random.default_rng(3)
    n = 101                                            # odd: the ranks get 51 and 50 frames
    vis = rng.choice([-1, 0, 1, 2, 3], n, p=[0.1, 0.2, 0.5, 0.1, 0.1])
    gt = rng.uniform(0, 500, (n, 2))
    pred_vis = rng.random(n) < 0.7
    pred_xy = np.where(pred_vis[:, None], gt + rng.normal(0, 8, (n, 2)), np.nan)
    score = rng.random(n)
    ev_y = rng.integers(0, 4, 77)
    ev_pred = np.where(rng.random(77) < 0.6, ev_y, rng.integers(0, 4, 77))
    data = tmp_path / "frames.npz"
    np.savez(data, vis=vis, gt=gt, pred_vis=pred_vis, pred_xy=pred_xy, score=score, ev_y=ev_y, ev_pred=ev_pred)
    script = tmp_path / "rank.py"
    script.write_text(RANK_SCRIPT)
    port = free_port()
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    procs = [subprocess.Popen([sys.executable, str(script), str(r), str(port), str(data)], stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True, env=env) for r in (0, 1)]
    outs = [p.communicate(timeout=600) for p in procs]
    for p, (out, err) in zip(procs, outs):
        assert p.returncode == 0, err[-3000:]
    results = [json.loads(next(l for l in out.splitlines() if l.startswith("RESULT "))[7:]) for out, _ in outs]
    single = evaluate_detections(pred_vis, pred_xy, score, vis, gt, tau_px=10.0, ignore_flags=(3,)).as_dict()
    f1_single = macro_event_f1(torch.as_tensor(ev_pred), torch.as_tensor(ev_y), 4)
    assert single["tp"] > 0 and single["fp1"] + single["fp2"] > 0 and single["fn"] > 0
    for r in results:
        rep = r["report"]
        assert {k: rep[k] for k in ("tp", "fp1", "fp2", "fn", "tn")} == {k: single[k] for k in ("tp", "fp1", "fp2", "fn", "tn")}
        assert rep["f1"] == pytest.approx(single["f1"], abs=1e-12)
        assert rep["rmse_px"] == pytest.approx(single["rmse_px"], rel=1e-9)
        assert rep["ap"] == pytest.approx(single["ap"], abs=1e-9)
        assert r["events"]["val/f1"] == pytest.approx(f1_single, abs=1e-12)
        assert r["events"]["val/acc"] == pytest.approx(float(np.mean(ev_pred == ev_y)), abs=1e-12)
    # one rank alone would not give these figures (the check can fail)
    half = evaluate_detections(pred_vis[::2], pred_xy[::2], score[::2], vis[::2], gt[::2], tau_px=10.0,
                               ignore_flags=(3,)).as_dict()
    assert half["tp"] != single["tp"]


# ------------------------------------------------------------------------------ evaluation shards
def test_eval_shards_cover_the_set_once_without_padding():
    from training.events.data.datamodule import BalancedSampler

    y = torch.tensor([0, 1, 0, 0, 2, 0, 0, 3, 0, 0, 0, 1, 0])
    base = BalancedSampler(y, 1.0, seed=4, fixed=True)
    assert list(base) == list(base)                      # validation: the same windows every epoch
    shards = [list(EvalShard(base, r, 2)) for r in (0, 1)]
    assert sorted(shards[0] + shards[1]) == sorted(base)  # union = the whole set, nothing repeated
    assert [len(EvalShard(base, r, 2)) for r in (0, 1)] == [len(s) for s in shards]
    ds = list(range(7))
    parts = [list(EvalShard(ds, r, 3)) for r in range(3)]
    assert sorted(sum(parts, [])) == ds and [len(p) for p in parts] == [3, 2, 2]
    one = type("T", (), {"world_size": 1, "global_rank": 0})()
    two = type("T", (), {"world_size": 2, "global_rank": 1})()
    assert eval_sampler(one, ds) is None and eval_sampler(None, ds) is None
    from torch.utils.data import DistributedSampler

    s = eval_sampler(two, ds)
    assert isinstance(s, DistributedSampler) and list(s) == [1, 3, 5]  # Lightning does not re-wrap it


# ------------------------------------------------------------------------------ unused parameters
def test_wasb_unused_parameters_frozen_and_kept_in_the_state_dict():
    from functools import partial

    from inference.models.registry import build_model
    from training.detection.losses import HeatmapLoss
    from training.detection.module import BallDetector

    plain = list(build_model("wasb").state_dict())
    det = BallDetector(build_model("wasb"), HeatmapLoss("wbce"), partial(torch.optim.Adam, lr=1e-3))
    assert len(det.unused) == 39 and all(n.startswith("stage4.0.fuse_layers.") for n in det.unused)
    assert [k.removeprefix("net.") for k in det.state_dict() if k.startswith("net.")] == plain
    det.train()
    x = torch.randn(2, 9, 32, 32)
    det(x).sum().backward()
    learning = [(n, p) for n, p in det.net.named_parameters() if p.requires_grad]
    assert all(p.grad is not None for _, p in learning)      # what DDP needs: no unused learnable parameter
    assert not any(n in det.unused for n, _ in learning)
    for name in ("tracknetv2", "monotrack"):
        other = BallDetector(build_model(name), HeatmapLoss("wbce"), partial(torch.optim.Adam, lr=1e-3))
        assert other.unused == []


def test_private_temp_paths_differ_and_keep_the_suffix(tmp_path):
    from inference.clipio import private_temp_path

    a, b = private_temp_path(tmp_path / "x.npy"), private_temp_path(tmp_path / "x.npy")
    assert a != b and a.suffix == ".npy" and a.parent == tmp_path and str(os.getpid()) in a.name
    np.save(a, np.zeros(2))
    assert a.is_file()                                       # np.save kept the name


# ------------------------------------------------------------------------------ ddp_sim (slow)
def _metrics_rows(run: Path) -> list[dict]:
    files = sorted(run.glob("csv/version_*/metrics.csv"))
    assert files, f"no metrics.csv under {run}"
    with files[-1].open() as f:
        return list(csv.DictReader(f))


def _last(rows: list[dict], key: str) -> float:
    vals = [float(r[key]) for r in rows if r.get(key) not in (None, "")]
    assert vals, f"{key} not logged"
    return vals[-1]


def _run_ddp(overrides: list[str], run: Path) -> None:
    env = {**os.environ, "PROJECT_ROOT": str(ROOT), "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, str(ROOT / "train.py"), *overrides, "trainer=ddp_sim", f"hydra.run.dir={run}"]
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=1500)
    assert out.returncode == 0, (out.stdout[-3000:], out.stderr[-5000:])
    assert "It is recommended to use `self.log(" not in out.stderr, out.stderr[-5000:]  # no advice that does not apply
    return out


def _validate_single(overrides: list[str], ckpt: Path, out: Path) -> tuple[dict[str, float], object]:
    """One process: the same config without DDP, validating the DDP run's checkpoint."""
    sys.path.insert(0, str(ROOT / "tests" / "training"))
    from test_template import compose_cfg  # noqa: E402 - the helper of the template tests

    from training.run import build

    cfg = compose_cfg([*overrides, "logger=csv"], out)
    dm, module, trainer = build(cfg)
    trainer.validate(module, datamodule=dm, ckpt_path=str(ckpt), weights_only=True)
    return {k: float(v) for k, v in trainer.callback_metrics.items()}, dm


@pytest.mark.slow
def test_ddp_sim_wasb_global_val_f1_equals_single_process(tmp_path):
    """WASB on a fresh tiny dataset, 2 gloo processes, fresh cache: the run's val/f1 and its TP/FP/FN are
    those one process measures with the same weights on the same validation clips."""
    from synth.generate import SynthConfig, generate_dataset

    data = tmp_path / "synth_padel"
    generate_dataset(data, 3, seed=8, config=SynthConfig(sport="padel", randomise_camera=False, width=320,
                                                         height=192, fps=30.0, codec="mp4v", randomise_look=False,
                                                         max_frames=33))  # 11 windows of 3: none repeats a frame
    cache = tmp_path / "cache"
    overrides = ["+experiment=wasb_padel", f"data.root={data}", "data.net_size=[96,160]", "data.crop=[64,64]",
                 "data.batch_size=2", f"data.cache_dir={cache}", "trainer.max_epochs=1",
                 "trainer.limit_train_batches=2", "test=false", "callbacks.progress_log.every_n_steps=1",
                 f"init_weights={ROOT / 'inference/weights/wasb_padel.pth.tar'}", "model.threshold=0.3"]
    run = tmp_path / "ddp"
    _run_ddp(overrides, run)
    rows = _metrics_rows(run)
    ddp = {k: _last(rows, f"val/{k}") for k in ("f1", "tp", "fp1", "fp2", "fn", "tn")}
    assert sorted(p.name for p in cache.iterdir()) == sorted(p.name for p in cache.glob("clip_*.npy"))  # no temp left
    assert len(list(cache.glob("*.npy"))) == 2                       # one per train/val clip (test=false)
    single, dm = _validate_single(overrides, run / "checkpoints" / "last.ckpt", tmp_path / "single")
    assert {k: single[f"val/{k}"] for k in ddp} == pytest.approx(ddp, abs=1e-6)
    ds = dm.data["val"]                                  # every labelled output frame of the val windows, once
    fi, fo = ds.spec.frames_in, ds.spec.frames_out
    frames = [ds.clips[c].visibility[s + fi - fo:s + fi] for c, s in ds.index]
    assert len(ds) % 2 == 1                              # odd: the ranks validate 6 and 5 windows (no padding)
    assert sum(ddp[k] for k in ("tp", "fp1", "fp2", "fn", "tn")) == sum(int(((v >= 0) & (v != 3)).sum()) for v in frames)
    assert ddp["tp"] > 0 and 0 < ddp["f1"] < 1
    print(f"WASB ddp_sim: 2 ranks {ddp}; one process {({k: single[f'val/{k}'] for k in ddp})}")
    assert (run / "wasb.pth.tar").is_file()


@pytest.mark.slow
def test_ddp_sim_hitnet_global_val_f1_equals_single_process(tmp_path):
    """HitNet on freshly simulated rallies (a fresh cache), 2 gloo processes: the run's val/f1 and val/acc
    are those one process measures with the same weights on the same validation windows."""
    overrides = ["+experiment=hitnet_padel", "data.n_train=6", "data.n_val=5", "data.n_test=2", "data.batch_size=16",
                 f"data.cache_dir={tmp_path / 'events_cache'}", "trainer.max_epochs=1",
                 "trainer.limit_train_batches=2", "test=false", "callbacks.progress_log.every_n_steps=1",
                 f"init_weights={ROOT / 'inference/weights/hitnet_padel.pth.tar'}", "model.lr=1e-5"]
    run = tmp_path / "ddp"
    _run_ddp(overrides, run)
    rows = _metrics_rows(run)
    ddp = {k: _last(rows, f"val/{k}") for k in ("f1", "acc")}
    cached = sorted(p.name for p in (tmp_path / "events_cache").iterdir())
    assert len(cached) == 2 and all(n.endswith(".pkl") for n in cached)          # train and val, built once, no temp
    single, _ = _validate_single(overrides, run / "checkpoints" / "last.ckpt", tmp_path / "single")
    assert single["val/f1"] == pytest.approx(ddp["f1"], abs=1e-6)
    assert single["val/acc"] == pytest.approx(ddp["acc"], abs=1e-6)
    assert 0.0 < ddp["acc"] < 1.0 and 0.0 < ddp["f1"] < 1.0          # the shipped weights: a real F1
    print(f"HitNet ddp_sim: 2 ranks {ddp}; one process val/f1 {single['val/f1']}, val/acc {single['val/acc']}")
    assert (run / "hitnet_padel.pth.tar").is_file()
