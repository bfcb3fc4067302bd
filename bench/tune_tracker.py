"""Tune and compare the ball tracker on cached detector output: our tracker against WASB's max-score.

    .venv/bin/python bench/tune_tracker.py                      # cache (once), then the comparison table
    .venv/bin/python bench/tune_tracker.py --sweep              # + a grid of tracker settings on val only
    .venv/bin/python bench/tune_tracker.py --root data/synth_padel --weights W --cache runs/tune_tracker

The network runs ONCE per clip of the ``val`` and ``test`` splits (the whole-clip pipeline of
:class:`~inference.detection.detect.BallDetectorRunner`: letterboxed non-overlapping 3-frame windows) and
its probability maps are cached as float16 under ``--cache`` (``runs/`` is git-ignored), keyed by the
weights' SHA-256. Everything after the network (heatmap → candidates at any threshold, tracker) then
runs from the cache in seconds, against each clip's ``ball.csv``, with the same rules as ``eval.py``:
only frames the tracker reports as *detected* count as "ball here", occluded frames (visibility 3) are
left out, τ = 4 px in original pixels and τ = 10 px at 1280×720. Settings are chosen on ``val`` only;
``test`` is reported, never tuned on. Prints Markdown; asserts nothing.
"""
from __future__ import annotations

import argparse
import hashlib
import itertools
import sys
import time
from dataclasses import dataclass, fields, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from inference.clipio import Clip, FormatError, Manifest  # noqa: E402
from inference.detection.geometry import Letterbox  # noqa: E402
from inference.detection.metrics import DetectionCounts, evaluate_ball_tracks  # noqa: E402
from inference.detection.postprocess import PostprocessConfig, heatmaps_to_candidates  # noqa: E402
from inference.detection.tracker import (  # noqa: E402
    TrackerConfig,
    TrackResult,
    TrackState,
    max_score_track,
    track_candidates,
)

SPLITS = ("val", "test")
TAUS = ((4.0, "τ=4 px original"), (10.0, "τ=10 px @1280×720"))


# -------------------------------------------------------------------------------------------- cache
@dataclass
class CachedClip:
    """One clip's detector output and ground truth.

    Attributes:
        maps: ``(T, H, W) float16`` probability maps (one per frame, non-overlapping windows).
        width, height, fps: the clip's frame size and rate; gt: its ``ball.csv``.
    """

    name: str
    split: str
    maps: np.ndarray
    width: int
    height: int
    fps: float
    gt: object

    def candidates(self, post: PostprocessConfig):
        """Per-frame candidates in original pixels at ``post``'s threshold."""
        net_h, net_w = self.maps.shape[1:]
        lb = Letterbox(self.width, self.height, net_w, net_h)
        return heatmaps_to_candidates(self.maps.astype(np.float32), lb, post)


def sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()[:16]


def cache_clip(clip: Clip, split: str, runner, out: Path) -> None:
    """Run the network over ``clip`` once and write its maps to ``out`` (npz, atomic rename)."""
    from tqdm import tqdm

    info = clip.info
    lb = Letterbox(info.width, info.height, runner.net_size[1], runner.net_size[0])
    with clip.frames(cache_size=0) as src:
        n = len(src)
        frames = (lb.warp(f) for f in tqdm(src.iter(), total=n, desc=f"network {clip.root.name}", unit="frame"))
        maps, _ = runner.heatmaps(frames)
    stack = np.zeros((n, *runner.net_size), np.float16)
    for i, m in maps.items():
        if i < n:
            stack[i] = np.max(m, axis=0).astype(np.float16)
    tmp = out.with_suffix(".tmp.npz")
    np.savez_compressed(tmp, maps=stack, width=info.width, height=info.height, fps=info.fps, split=split)
    tmp.replace(out)


def load_cache(root: Path, weights: Path, cache: Path) -> list[CachedClip]:
    """The cached clips of ``SPLITS``, running the network on those not cached yet."""
    from inference.detection.detect import BallDetectorRunner

    manifest = Manifest.load(root)
    folder = cache / f"{root.name}_{sha256(weights)}"
    folder.mkdir(parents=True, exist_ok=True)
    runner = None
    out = []
    for split in SPLITS:
        for path in manifest.paths(split):
            clip = Clip(path)
            file = folder / f"{path.name}.npz"
            if not file.is_file():
                if runner is None:
                    runner = BallDetectorRunner.from_weights("wasb", weights)
                t0 = time.perf_counter()
                cache_clip(clip, split, runner, file)
                print(f"cached {file} in {time.perf_counter() - t0:.0f} s", file=sys.stderr)
            with np.load(file) as z:
                out.append(CachedClip(path.name, split, z["maps"], int(z["width"]), int(z["height"]),
                                      float(z["fps"]), clip.read_ball(n_frames=len(z["maps"]))))
    if not out:
        raise FormatError(f"{root / 'manifest.yaml'}: no clips in the splits {SPLITS}")
    return out


# ----------------------------------------------------------------------------------------- scoring
def counts_of(result: TrackResult, clip: CachedClip, tau_1280: float | None, tau_px: float
              ) -> DetectionCounts:
    """Outcome counts of one clip, as ``eval.py`` measures them (detections only, visibility 3 ignored)."""
    pred = result.to_ball_track(clip.width, clip.height, coast_visibility=0)
    tau = tau_px if tau_1280 is None else tau_1280 * clip.width / 1280.0
    rep = evaluate_ball_tracks(pred, clip.gt, clip.width, clip.height, tau_px=tau, ignore_flags=(3,))
    return rep.counts


class Evaluator:
    """Scores tracker settings on cached clips; candidates are cached per postprocess config."""

    def __init__(self, clips: list[CachedClip]) -> None:
        self.clips = clips
        self._cands: dict[PostprocessConfig, list] = {}

    def candidates(self, post: PostprocessConfig) -> list:
        if post not in self._cands:
            self._cands[post] = [c.candidates(post) for c in self.clips]
        return self._cands[post]

    def score(self, split: str, method: str, post: PostprocessConfig = PostprocessConfig(),
              tracker: TrackerConfig = TrackerConfig()) -> dict[str, DetectionCounts]:
        """``{tau name: summed counts}`` over the clips of ``split``."""
        total = {name: DetectionCounts() for _, name in TAUS}
        for clip, cands in zip(self.clips, self.candidates(post)):
            if clip.split != split:
                continue
            if method == "max-score":
                result = max_score_track(cands)
            else:
                result = track_candidates(cands, clip.fps, tracker, (clip.width, clip.height))
            for tau, name in TAUS:
                total[name] = total[name] + counts_of(result, clip, tau if tau == 10.0 else None, tau)
        return total


def table(ev: Evaluator, post: PostprocessConfig, tracker: TrackerConfig, baseline_post: PostprocessConfig
          ) -> str:
    """Markdown: tracker vs max-score, per split and τ, precision / recall / F1 (%)."""
    lines = ["| split | τ | method | F1 (%) | Precision (%) | Recall (%) | TP | FP1 | FP2 | FN |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for split in SPLITS:
        n = sum(len(c.maps) for c in ev.clips if c.split == split)
        k = sum(c.split == split for c in ev.clips)
        rows = [("max-score (WASB-SBDT)", ev.score(split, "max-score", baseline_post)),
                ("rally3d tracker", ev.score(split, "tracker", post, tracker))]
        for _, tau in TAUS:
            for name, res in rows:
                c = res[tau]
                lines.append(f"| {split} ({k} clips, {n} frames) | {tau} | {name} | {100 * c.f1:.1f} | "
                             f"{100 * c.precision:.1f} | {100 * c.recall:.1f} | {c.tp} | {c.fp1} | {c.fp2} | {c.fn} |")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------- sweep
def sweep(ev: Evaluator, base: TrackerConfig, post: PostprocessConfig, grid: dict[str, list]
          ) -> list[tuple[float, dict, dict]]:
    """F1 on **val** (mean of the two τ) of every combination of ``grid`` over ``base``; best first."""
    from tqdm import tqdm

    names = list(grid)
    out = []
    combos = list(itertools.product(*(grid[k] for k in names)))
    for values in tqdm(combos, desc="sweep (val)"):
        kw = dict(zip(names, values))
        p = replace(post, **{k[5:]: v for k, v in kw.items() if k.startswith("post.")})
        t = replace(base, **{k: v for k, v in kw.items() if not k.startswith("post.")})
        res = ev.score("val", "tracker", p, t)
        f1 = float(np.mean([c.f1 for c in res.values()]))
        out.append((f1, kw, {k: (round(c.precision, 3), round(c.recall, 3)) for k, c in res.items()}))
    return sorted(out, key=lambda r: -r[0])


def parse_value(text: str):
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"true": True, "false": False, "inf": float("inf")}.get(text.lower(), text)


def main(argv=None) -> None:
    from inference.detection.detect import SHIPPED

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--root", type=Path, default=ROOT / "data/synth_padel")
    ap.add_argument("--weights", type=Path, default=SHIPPED["wasb"])
    ap.add_argument("--cache", type=Path, default=ROOT / "runs/tune_tracker")
    ap.add_argument("--threshold", type=float, default=PostprocessConfig().threshold,
                    help="heatmap threshold of the tracker's candidates (max-score keeps 0.5, as WASB)")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                    help="TrackerConfig overrides for the table, e.g. confirm_frames=2")
    ap.add_argument("--sweep", nargs="*", default=None, metavar="KEY=V1,V2",
                    help="grid over TrackerConfig fields (post.threshold for the postprocess), val only")
    args = ap.parse_args(argv)
    for p in (args.root / "manifest.yaml", args.weights):
        if not p.is_file():
            raise SystemExit(f"{p} not found (generate the data set with `rally3d synth`, see the README)")
    clips = load_cache(args.root, args.weights, args.cache)
    ev = Evaluator(clips)
    known = {f.name for f in fields(TrackerConfig)}
    overrides = {}
    for item in args.set:
        key, _, value = item.partition("=")
        if key not in known:
            raise SystemExit(f"--set {item}: unknown TrackerConfig field {key!r}")
        overrides[key] = parse_value(value)
    tracker = replace(TrackerConfig(), **overrides)
    post = replace(PostprocessConfig(), threshold=args.threshold)
    if args.sweep is not None:
        grid = {}
        for item in args.sweep:
            key, _, values = item.partition("=")
            if key not in known and not key.startswith("post."):
                raise SystemExit(f"--sweep {item}: unknown TrackerConfig field {key!r}")
            grid[key] = [parse_value(v) for v in values.split(",")]
        for f1, kw, pr in sweep(ev, tracker, post, grid)[:15]:
            print(f"val F1 {100 * f1:.2f}  {kw}  (P, R) {pr}")
        print()
    print(f"{args.root} ({', '.join(SPLITS)} splits), weights {args.weights.name}; tracker threshold "
          f"{post.threshold:g}, max-score threshold 0.5; detections only, visibility 3 ignored\n")
    print(table(ev, post, tracker, PostprocessConfig()))


if __name__ == "__main__":
    main()
