"""Inference speed of the ball detectors at 288×512 on this machine (CPU; GPU when there is one).

    .venv/bin/python bench/bench_detectors.py [--repeats 3] [--batches 1,4]

For each model: eager (train-mode graph, autograd on) against optimised variants measured in the same run —
``inference_mode``, channels_last memory layout, batch-norm folded into the convolutions, torch.compile
(where it helps), and bf16/fp16 autocast on a GPU — as frames/s (3 frames per window) and as ratios to
eager. Prints Markdown; asserts nothing.
"""
from __future__ import annotations

import argparse
import copy
import time

import torch
from torch import nn

from inference.models.fuse import fold_batchnorm
from inference.models.registry import MODEL_NAMES, build_model


def timed(fn, x, repeats: int) -> float:
    fn(x)  # warm-up
    if x.is_cuda:
        torch.cuda.synchronize()
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn(x)
        if x.is_cuda:
            torch.cuda.synchronize()
        best = min(best, time.perf_counter() - t0)
    return best


def variants(model: nn.Module, device: str) -> dict:
    eager = model.train(False)

    def run_eager(x):
        return eager(x)

    def run_inference(x):
        with torch.inference_mode():
            return eager(x)

    cl = copy.deepcopy(model).eval().to(memory_format=torch.channels_last)

    def run_cl(x):
        with torch.inference_mode():
            return cl(x.contiguous(memory_format=torch.channels_last))

    folded, n_folded = fold_batchnorm(model)
    if not n_folded:
        folded = None

    out = {"eager": run_eager, "inference_mode": run_inference, "channels_last": run_cl}
    if folded is not None:
        def run_folded(x):
            with torch.inference_mode():
                return folded(x.contiguous(memory_format=torch.channels_last))
        folded = folded.to(memory_format=torch.channels_last)
        out[f"BN folded ({n_folded} pairs) + channels_last"] = run_folded
    if device == "cuda":
        def run_amp(x):
            with torch.inference_mode(), torch.autocast("cuda", dtype=torch.bfloat16):
                return cl(x.contiguous(memory_format=torch.channels_last))
        out["bf16 autocast"] = run_amp
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--batches", default="1,4")
    ap.add_argument("--compile", action="store_true", help="also torch.compile (slow to compile on a CPU)")
    args = ap.parse_args()
    device = "cuda" if torch.cuda.is_available() else "cpu"
    batches = [int(b) for b in args.batches.split(",")]
    print(f"device: {device}, torch {torch.__version__}, threads {torch.get_num_threads()}; input (B, 9, 288, 512)\n")
    print("| model | variant | " + " | ".join(f"batch {b} frames/s" for b in batches) + " | ratio to eager (batch 1) |")
    print("|---|---|" + "---|" * len(batches) + "---|")
    for name in MODEL_NAMES:
        model = build_model(name).to(device).eval()
        runs = variants(model, device)
        if args.compile:
            compiled = torch.compile(copy.deepcopy(model).eval())

            def run_compiled(x, m=compiled):
                with torch.inference_mode():
                    return m(x)
            runs["torch.compile"] = run_compiled
        base = None
        for label, fn in runs.items():
            fps = []
            for b in batches:
                x = torch.randn(b, 9, 288, 512, device=device)
                fps.append(3 * b / timed(fn, x, args.repeats))
            base = base or fps[0]
            print(f"| {name} | {label} | " + " | ".join(f"{f:.1f}" for f in fps) + f" | {fps[0] / base:.2f} |",
                  flush=True)


if __name__ == "__main__":
    main()
