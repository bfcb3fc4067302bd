"""Benchmark fine-tuning on a few clips of unseen-looking footage: the shipped padel WASB before and after
fine-tuning, against training from scratch and other recipes (``--arms``, :data:`ARMS`) with the same
steps. Prints figures; asserts nothing.

    .venv/bin/python bench/bench_finetune.py [--train-clips 6] [--test-clips 4] [--steps 300] [--threads 1]
        [--arms recipe,scratch,lr1e-3,unfrozen,full,blob_val] [--parallel]

The clips stand in for real footage: rendered padel rallies whose look is drawn from another distribution
than the shipped weights' training set (``SynthConfig(look_shift=True)``: other floors, dim tinted light,
noise, heavy JPEG, blur, a paler ball). ``--train-clips`` clips train (one more validates), ``--test-clips``
held-out clips of the same distribution score every model, whole clips at full resolution as inference runs
(``eval.py``: τ = 10 px at 1280×720, the rally3d tracker and WASB-SBDT's max-score post-processing).
Every arm runs the real commands (``train.py +experiment=wasb_padel_finetune``, ``eval.py``) in a child
process; its CPU time (user + system, all threads) is that child's own (``os.wait4``). The data are
generated once under ``--data`` and reused.
"""
from __future__ import annotations

import argparse
from concurrent.futures import ThreadPoolExecutor
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def make_data(root: Path, n_train: int, n_test: int, seed: int, max_frames: int) -> None:
    """n_train + 1 (val) + n_test shifted-look clips with a manifest (generated once)."""
    from inference.clipio import Manifest, ManifestEntry
    from synth.generate import SynthConfig, generate_clip

    if (root / "manifest.yaml").is_file():
        return
    cfg = SynthConfig(sport="padel", look_shift=True, max_frames=max_frames)
    splits = ["train"] * n_train + ["val"] + ["test"] * n_test
    entries = []
    t0 = time.perf_counter()
    for k, split in enumerate(splits):
        name = f"clip_{k:04d}"
        generate_clip(root / name, seed * 1000 + k, cfg)
        entries.append(ManifestEntry(name, split))
        print(f"  rendered {name} ({split}), {time.perf_counter() - t0:.0f} s", flush=True)
    Manifest(root, entries, name=root.name, sport="padel",
             source=f"bench_finetune: look_shift, seed {seed}").save()


def run(cmd: list[str], log: Path, threads: int) -> float:
    """Run a command (output to ``log``); returns its CPU seconds (user + system, every thread), from the
    child's own resource usage (so commands can run side by side)."""
    env = {**os.environ, "OMP_NUM_THREADS": str(threads), "MKL_NUM_THREADS": str(threads), "PYTHONPATH": str(ROOT)}
    with log.open("w") as f:
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=f, stderr=subprocess.STDOUT, env=env)
        _, status, usage = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        raise SystemExit(f"failed ({proc.returncode}): {' '.join(cmd)} — see {log}")
    return usage.ru_utime + usage.ru_stime


def evaluate(ckpt: Path, data: Path, out: Path, threads: int, reuse: bool = False) -> tuple[dict[str, float], float]:
    """F1 of ``ckpt`` on the test clips (``eval.py``) and its CPU seconds; ``reuse``: an earlier result of
    the same checkpoint and data (the shipped weights) is read instead of recomputed."""
    cpu_file = out / "cpu_s.txt"
    if reuse and cpu_file.is_file() and (out / "results.json").is_file():
        cpu = float(cpu_file.read_text())
    else:
        cpu = run([sys.executable, "eval.py", "+experiment=wasb_padel", f"ckpt_path={ckpt}", f"data.root={data}",
                   "split=test", "batch_size=1", f"hydra.run.dir={out}"], out.with_suffix(".log"), threads)
        cpu_file.write_text(f"{cpu}\n")
    rows = json.loads((out / "results.json").read_text())["rows"]
    f1 = {f"{r['post']} τ{r['tau_px']:g}": r["f1"] for r in rows if r.get("table", "").startswith("tau")}
    return f1, cpu


ARMS = {  # name → (what the table says, train.py overrides beyond the common ones)
    "recipe": ("fine-tuned (the wasb_padel_finetune recipe)", ["+experiment=wasb_padel_finetune"]),
    "scratch": ("from scratch (lr 1e-3)", ["+experiment=wasb_padel_finetune", "init_weights=null", "model.freeze=[]",
                                            "model.optimizer.lr=1e-3"]),
    "lr1e-3": ("fine-tuned, stem frozen, lr 1e-3", ["+experiment=wasb_padel_finetune", "model.optimizer.lr=1e-3"]),
    "unfrozen": ("fine-tuned, nothing frozen, lr 2e-4", ["+experiment=wasb_padel_finetune", "model.freeze=[]"]),
    "full": ("fine-tuned on full frames (no crops), batch 2", ["+experiment=wasb_padel_finetune", "data.crop=null",
                                                                "data.batch_size=2"]),
    "blob_val": ("fine-tuned, best epoch by the per-frame blob F1 (before issue 41)",
                 ["+experiment=wasb_padel_finetune", "model.val_post=blob", "model.tau_px=10"]),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--train-clips", type=int, default=6)
    ap.add_argument("--test-clips", type=int, default=4)
    ap.add_argument("--max-frames", type=int, default=150)
    ap.add_argument("--steps", type=int, default=300, help="training steps of each arm (batches of 8 crops)")
    ap.add_argument("--epochs", type=int, default=4)
    ap.add_argument("--val-batches", type=int, default=10, help="validation batches per epoch (best-epoch choice)")
    ap.add_argument("--parallel", action="store_true", help="run the two arms side by side (CPU time is per arm)")
    ap.add_argument("--threads", type=int, default=1, help="torch threads of each child (CPU time is reported)")
    ap.add_argument("--seed", type=int, default=77)
    ap.add_argument("--arms", default="recipe,scratch", help=f"comma-separated recipes to compare ({', '.join(ARMS)})")
    ap.add_argument("--data", type=Path, default=ROOT / "runs" / "bench_finetune" / "data")
    ap.add_argument("--out", type=Path, default=ROOT / "runs" / "bench_finetune")
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    print(f"data: {a.data} ({a.train_clips} train + 1 val + {a.test_clips} test clips, shifted look)", flush=True)
    make_data(a.data, a.train_clips, a.test_clips, a.seed, a.max_frames)
    per_epoch = max(1, a.steps // a.epochs)
    common = [f"data.root={a.data}", f"trainer.max_epochs={a.epochs}", f"trainer.limit_train_batches={per_epoch}",
              f"trainer.limit_val_batches={a.val_batches}",
              "test=false", "seed=1", "+trainer.num_sanity_val_steps=0"]
    arms = {name: ARMS[name][1] for name in a.arms.split(",")}
    arms = {ARMS[name][0]: extra for name, extra in arms.items()}
    shipped = ROOT / "inference" / "weights" / "wasb_padel.pth.tar"
    results = [("shipped weights, not fine-tuned", 0.0, *evaluate(shipped, a.data, a.out / "eval_shipped", a.threads,
                                                                 reuse=True))]
    print(f"  {results[-1]}", flush=True)
    def arm(k: int, name: str, extra: list[str]) -> tuple:
        run_dir = a.out / f"arm{k}"
        cpu = run([sys.executable, "train.py", *extra, *common, f"hydra.run.dir={run_dir}"], run_dir.with_suffix(".log"),
                  a.threads)
        f1, eval_cpu = evaluate(run_dir / "wasb.pth.tar", a.data, a.out / f"eval_arm{k}", a.threads)
        print(f"  {(name, cpu, f1, eval_cpu)}", flush=True)
        return name, cpu, f1, eval_cpu

    with ThreadPoolExecutor(len(arms) if a.parallel else 1) as pool:  # CPU times are per child either way
        results += list(pool.map(lambda item: arm(item[0], *item[1]), enumerate(arms.items())))
    keys = list(results[0][2])
    print(f"\nFine-tuning on {a.train_clips} shifted-look padel clips ({per_epoch * a.epochs} steps × 8 crops of "
          f"128×128, {a.threads} thread), F1 on {a.test_clips} held-out clips of that look (whole clips, τ = 10 px "
          f"at 1280×720 and 4 px original):\n")
    print("| model | training CPU time | " + " | ".join(f"F1 {k}" for k in keys) + " |")
    print("|---|---|" + "---|" * len(keys))
    for name, cpu, f1, _ in results:
        cells = " | ".join(f"{100 * f1[k]:.1f} %" for k in keys)
        print(f"| {name} | {cpu / 60:.1f} min | {cells} |")
    print(f"\n(evaluation CPU time per arm: {', '.join(f'{r[3] / 60:.1f} min' for r in results)})")


if __name__ == "__main__":
    main()
