"""The ball detectors' data path before and after the frame store, on the same clips in one run: disk beside
the data, build time, RSS and samples/s of ``BallWindows.__getitem__``; the JPEG quality against what
training saw before (whole frame and around the ball) and, with ``--detector``, the shipped WASB's output on
the same windows from both. Prints figures; asserts nothing.

    .venv/bin/python bench/bench_data_path.py [--data DIR] [--clips 6] [--samples 1000] [--workers 2]
                                              [--qualities 85,90,95] [--detector]

Before: every letterboxed frame as raw ``uint8`` in one ``.npy`` memmap per clip (the cache of earlier
versions, rebuilt here the way they built it). After: :mod:`training.detection.frame_store` (JPEG, one
indexed file per clip, decoded in ``__getitem__``, per-process LRU; PNG for the validation and test splits).
Each data path runs in a fresh process (so its RSS is its own): ``crop`` is the training path (128×128
crops, augmentation, windows at step 1 in a shuffled order), ``full`` the validation path (full frames,
step 3, in order); ``cold`` first drops the files from the page cache (``posix_fadvise``), as for data
larger than the memory.

Clips: ``--data`` (default ``data/synth_padel`` when it exists, else 6 clips of ``rally3d synth --seed 10
--max-frames 300`` made once in ``runs/bench_data_path/synth``, about 1.5 min).
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
WORK = ROOT / "runs" / "bench_data_path"
NET = (288, 512)


def proc_status(pid: int | str = "self") -> dict[str, int]:
    """VmRSS, VmHWM, RssAnon, RssFile of a process in bytes."""
    out = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmRSS", "VmHWM", "RssAnon", "RssFile"):
            out[key] = int(value.split()[0]) * 1024
    return out


def children_rss() -> int:
    """Summed RSS of this process's children (DataLoader workers)."""
    me, total = str(os.getpid()), 0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            if fields[1] == me:
                total += proc_status(stat.parent.name).get("VmRSS", 0)
        except (OSError, IndexError):
            continue
    return total


def evict(paths) -> None:
    """Drop these files' pages from the page cache (their next read comes from the disk)."""
    for p in paths:
        fd = os.open(p, os.O_RDONLY)
        try:
            os.fsync(fd)
            os.posix_fadvise(fd, 0, 0, os.POSIX_FADV_DONTNEED)
        finally:
            os.close(fd)


def dataset_clips(args) -> list[Path]:
    data = Path(args.data) if args.data else None
    if data is None:
        data = ROOT / "data" / "synth_padel"
        if not (data / "manifest.yaml").is_file():
            data = WORK / "synth"
            if not (data / "manifest.yaml").is_file():
                print(f"making 6 clips in {data} (rally3d synth, about 1.5 min)", flush=True)
                subprocess.run([str(Path(sys.executable).with_name("rally3d")), "synth", "--sport", "padel",
                                "--clips", "6", "--out", str(data), "--seed", "10", "--max-frames", "300"],
                               check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    clips = sorted(p for p in data.iterdir() if (p / "clip.yaml").is_file() and (p / "ball.csv").is_file())
    return clips[:args.clips]


def build_raw(clip_dir: Path, out: Path) -> Path:
    """The raw cache of earlier versions: every letterboxed frame, uint8, in one .npy memmap."""
    from inference.clipio import Clip
    from inference.detection.geometry import Letterbox

    clip = Clip(clip_dir)
    path = out / f"{clip.root.name}.npy"
    info, n = clip.info, clip.n_frames
    lb = Letterbox(info.width, info.height, NET[1], NET[0])
    tmp = path.with_suffix(".tmp.npy")
    arr = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.uint8, shape=(n, *NET, 3))
    with clip.frames(cache_size=0) as src:
        for i, frame in enumerate(src.iter(0, n)):
            arr[i] = lb.warp(frame)
    arr.flush()
    del arr
    tmp.replace(path)
    return path


def load(clip_dirs, store_dir: Path, raw_dir: Path | None, exact: bool = False):
    """ClipData of every clip: frames from the store (``exact``: the lossless one of the scored splits), or
    (raw_dir) from the raw memmaps."""
    from inference.clipio import Clip
    from training.detection.data import load_clip

    out = []
    for d in clip_dirs:
        cd = load_clip(Clip(d), NET, store_dir, exact=exact)
        if raw_dir is not None:
            cd = dataclasses.replace(cd, frames=np.load(raw_dir / f"{d.name}.npy", mmap_mode="r"))
        out.append(cd)
    return out


def child(cfg: dict) -> None:
    """One data path in a fresh process: prints a JSON line."""
    import torch

    from training.detection import frame_store
    from training.detection.data import BallWindows, WindowSpec, collate

    torch.set_num_threads(1)
    raw = Path(cfg["raw"]) if cfg["raw"] else None
    clips = load([Path(p) for p in cfg["clips"]], Path(cfg["store"]), raw, cfg.get("exact", False))
    train = cfg["mode"] == "crop"
    spec = WindowSpec(crop=(128, 128) if train else None, augment=train, step=1 if train else 3)
    ds = BallWindows(clips, spec, seed=0)
    order = np.random.default_rng(0).permutation(len(ds)) if train else np.arange(len(ds))
    order = [int(i) for i in order[:cfg["samples"]]]
    rss0 = proc_status()
    frame_store.LRU.clear()
    t0, cpu0 = time.perf_counter(), time.process_time()
    if cfg["workers"]:
        from torch.utils.data import DataLoader

        loader = DataLoader(ds, batch_size=8, sampler=order, num_workers=cfg["workers"], collate_fn=collate,
                            multiprocessing_context="fork")
        it, workers_rss = iter(loader), 0
        for k, _ in enumerate(it):
            if k == len(loader) // 2:
                workers_rss = children_rss()
        del it
    else:
        workers_rss = 0
        for i in order:
            ds[i]
    dt, cpu = time.perf_counter() - t0, time.process_time() - cpu0
    rss1 = proc_status()
    print(json.dumps({"samples_s": len(order) / dt, "n": len(order), "cpu_ms": cpu / len(order) * 1e3,
                      "rss0": rss0["VmRSS"], "rss": rss1["VmRSS"], "hwm": rss1["VmHWM"],
                      "rss_file": rss1["RssFile"], "rss_anon": rss1["RssAnon"],
                      "workers_rss": workers_rss, "lru_hits": frame_store.LRU.hits,
                      "lru_misses": frame_store.LRU.misses}))


def run_child(cfg: dict) -> dict:
    out = subprocess.run([sys.executable, __file__, "--child", json.dumps(cfg)], capture_output=True,
                         text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)})
    if out.returncode:
        raise RuntimeError(out.stderr[-3000:])
    return json.loads(out.stdout.strip().splitlines()[-1])


def quality_table(clip_dirs, raw_dir: Path, store_dir: Path, qualities, per_clip: int = 40) -> None:
    """JPEG size, error (whole frame, and a 9×9 patch around each visible ball) and decode time per quality,
    on frames of the raw cache (what training saw before)."""
    from training.detection.frame_store import decode_frame, encode_frame

    clips = load(clip_dirs, store_dir, raw_dir)
    video = sum((d / "video.mp4").stat().st_size for d in clip_dirs if (d / "video.mp4").is_file())
    n_total = sum(len(c.frames) for c in clips)
    print(f"\nJPEG at {NET[0]}×{NET[1]} against the raw frames ({per_clip} frames per clip; videos "
          f"{video / 1e6:.1f} MB for {n_total} frames):")
    print("| quality | kB/frame | whole set, MB (× videos) | PSNR dB | mean abs err "
          "| ball patch mean / p99 / max abs err | decode ms/frame |")
    print("|---|---|---|---|---|---|---|")
    for q, sub in qualities:
        sizes, sq, ab, ball, dec = [], [], [], [], []
        for c in clips:
            pick = np.linspace(0, len(c.frames) - 1, per_clip).astype(int)
            for i in pick:
                f = np.asarray(c.frames[i])
                buf = encode_frame(f, "jpeg", q, sub)
                t0 = time.perf_counter()
                g = decode_frame(buf)
                dec.append(time.perf_counter() - t0)
                e = g.astype(np.int16) - f
                sizes.append(len(buf))
                sq.append(float((e.astype(np.float64) ** 2).mean()))
                ab.append(float(np.abs(e).mean()))
                x, y = c.xy_net[i]
                if c.visibility[i] in (1, 2) and np.isfinite(x):
                    x, y = round(x), round(y)
                    patch = e[max(y - 4, 0):y + 5, max(x - 4, 0):x + 5]
                    ball.append(np.abs(patch).ravel())
        ball = np.concatenate(ball) if ball else np.zeros(1)
        kb = np.mean(sizes)
        whole = kb * n_total
        psnr = 10 * np.log10(255 ** 2 / np.mean(sq))
        print(f"| {q} {sub} | {kb / 1e3:.1f} | {whole / 1e6:.1f} ({whole / video:.2f}×) | {psnr:.1f} | "
              f"{np.mean(ab):.2f} | {ball.mean():.2f} / {np.percentile(ball, 99):.0f} / {ball.max()} | "
              f"{np.median(dec) * 1e3:.2f} |")


def detector_check(clip_dirs, raw_dir: Path, store_dir: Path, frames: int) -> None:
    """The shipped WASB on the same full-frame windows from the raw cache and from the store."""
    import torch

    from inference.detection.detect import BallDetectorRunner
    from inference.detection.postprocess import heatmap_to_candidates

    torch.set_num_threads(max(os.cpu_count() or 1, 1))
    runner = BallDetectorRunner.from_weights("wasb", batch_size=4)
    raw = load(clip_dirs, store_dir, raw_dir)
    new = load(clip_dirs, store_dir, None)
    per = max(frames // len(raw), 3)
    dmax, dpos, hits = [], [], {"raw": 0, "store": 0}
    n_vis = 0
    t0 = time.perf_counter()
    for a, b in zip(raw, new):
        m = min(per, len(a.frames)) // 3 * 3
        ha, _ = runner.heatmaps([np.asarray(a.frames[i]) for i in range(m)])
        hb, _ = runner.heatmaps([b.frames[i] for i in range(m)])
        for i in range(m):
            pa, pb = ha[i][0], hb[i][0]
            dmax.append(float(np.abs(pa - pb).max()))
            top = []
            for p in (pa, pb):
                c = heatmap_to_candidates(p)
                top.append(c.xy[np.argmax(c.score)] if len(c.score) else None)
            if top[0] is not None and top[1] is not None:
                dpos.append(float(np.linalg.norm(np.asarray(top[0]) - top[1])))
            if a.visibility[i] in (1, 2) and np.isfinite(a.xy_net[i]).all():
                n_vis += 1
                scale = pa.shape[1] / NET[1]
                for name, t in zip(("raw", "store"), top):
                    if t is not None and np.linalg.norm(np.asarray(t) / scale - a.xy_net[i]) <= 4:
                        hits[name] += 1
    print(f"\nshipped WASB on {len(dmax)} frames from the raw cache and from the store "
          f"({time.perf_counter() - t0:.0f} s): heatmap max |Δp| median {np.median(dmax):.3f}, "
          f"p95 {np.percentile(dmax, 95):.3f}; top detection moved median {np.median(dpos):.2f} px, "
          f"p95 {np.percentile(dpos, 95):.2f} px (net pixels, {len(dpos)} frames with one in both); "
          f"ball found within 4 net px: raw {hits['raw']}/{n_vis}, store {hits['store']}/{n_vis}")


def du(paths) -> int:
    return sum(p.stat().st_size for p in paths)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", help="dataset folder or folder of clip folders (default: see the docstring)")
    ap.add_argument("--clips", type=int, default=6)
    ap.add_argument("--samples", type=int, default=1000, help="windows per data path and mode")
    ap.add_argument("--workers", type=int, default=0, help="also through a DataLoader with this many workers")
    ap.add_argument("--qualities", default="85,90,95,95:444", help="JPEG qualities to compare (q or q:444)")
    ap.add_argument("--detector", action="store_true", help="also the shipped WASB on windows from both")
    ap.add_argument("--detector-frames", type=int, default=240)
    ap.add_argument("--child", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(json.loads(args.child))
        return

    from training.detection import frame_store

    clip_dirs = dataset_clips(args)
    raw_dir, store_dir = WORK / "raw_cache", WORK / "store"
    shutil.rmtree(store_dir, ignore_errors=True)
    shutil.rmtree(raw_dir, ignore_errors=True)
    raw_dir.mkdir(parents=True, exist_ok=True)
    video = du([d / "video.mp4" for d in clip_dirs if (d / "video.mp4").is_file()])
    t0 = time.perf_counter()
    raw_files = [build_raw(d, raw_dir) for d in clip_dirs]
    t_raw = time.perf_counter() - t0
    t0 = time.perf_counter()
    clips = load(clip_dirs, store_dir, None)
    t_store = time.perf_counter() - t0
    store_files = sorted(store_dir.glob("*.npy"))
    t0 = time.perf_counter()
    load(clip_dirs, store_dir, None, exact=True)
    t_png = time.perf_counter() - t0
    png_files = sorted(set(store_dir.glob("*.npy")) - set(store_files))
    n = sum(len(c.frames) for c in clips)
    print(f"{len(clip_dirs)} clips, {n} frames at {NET[0]}×{NET[1]}, videos {video / 1e6:.1f} MB; store JPEG "
          f"q{frame_store.QUALITY} {frame_store.SUBSAMPLING}, LRU {frame_store.LRU.max_bytes / 2**20:.0f} MB")
    print(f"disk: raw cache {du(raw_files) / 1e6:.0f} MB (built in {t_raw:.0f} s), frame store "
          f"{du(store_files) / 1e6:.1f} MB (built in {t_store:.0f} s) = {du(store_files) / video:.2f}× the "
          "videos, "
          f"1/{du(raw_files) / du(store_files):.1f} of the raw cache; lossless store of the scored splits "
          f"{du(png_files) / 1e6:.0f} MB for the same clips (built in {t_png:.0f} s), 1/"
          f"{du(raw_files) / du(png_files):.1f} of the raw cache")

    base = {"clips": [str(d) for d in clip_dirs], "store": str(store_dir), "samples": args.samples,
            "workers": 0}
    rows = []
    for mode, cold in (("crop", True), ("crop", False), ("full", False)):
        paths = [("raw uint8 memmap (before)", str(raw_dir), False, raw_files),
                 ("JPEG frame store (after)", None, False, store_files)]
        if mode == "full":
            paths.append(("PNG frame store, val/test (after)", None, True, png_files))
        for name, raw, exact, files in paths:
            cfg = {**base, "raw": raw, "mode": mode, "exact": exact}
            if cold:
                evict(files)
            else:
                run_child({**cfg, "samples": 50})  # warms the page cache
            rows.append((mode + (" cold" if cold else ""), name, run_child(cfg)))
            if args.workers and not cold:
                r = run_child({**cfg, "workers": args.workers})
                rows.append((f"{mode}, DataLoader {args.workers} workers", name, r))
    print("\n| mode | data path | samples/s | CPU ms/sample | RSS at start → end, MB (file-backed) "
          "| peak RSS MB | workers' RSS MB | LRU hits |")
    print("|---|---|---|---|---|---|---|---|")
    for mode, name, r in rows:
        lru = r["lru_hits"] + r["lru_misses"]
        cpu = f"{r['cpu_ms']:.1f}" if not r["workers_rss"] else "-"
        print(f"| {mode} | {name} | {r['samples_s']:.1f} | {cpu} | "
              f"{r['rss0'] / 1e6:.0f} → {r['rss'] / 1e6:.0f} "
              f"({r['rss_file'] / 1e6:.0f}) | {r['hwm'] / 1e6:.0f} | "
              f"{r['workers_rss'] / 1e6:.0f} | {format(r['lru_hits'] / lru, '.0%') if lru else '-'} |")
    print(f"({args.samples} windows per row; crop: 128×128, augmented, step 1, shuffled; "
          "full: step 3, in order)")

    qualities = []
    for q in args.qualities.split(","):
        value, _, sub = q.partition(":")
        qualities.append((int(value), sub or "420"))
    quality_table(clip_dirs, raw_dir, store_dir, qualities)
    if args.detector:
        detector_check(clip_dirs, raw_dir, store_dir, args.detector_frames)


if __name__ == "__main__":
    main()
