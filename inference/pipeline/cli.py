"""``rally3d infer``: a video (or clip folder, or dataset) → ball.csv, events.csv, players.csv, ball_3d.csv."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .match import MATCH_ABOVE_S, MatchParams

STAGE_NAMES = ("camera", "scenes", "detect", "smooth", "players", "events", "reconstruct")
#: former stage names --only still takes (deprecated), and the stage each now is
STAGE_ALIASES = {"shots": "scenes"}  # the scenes stage (between the editor's cuts) before issue 43


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "infer",
        help="run the whole pipeline on a video or clip: ball, hit events, players, 3D (writes a clip folder)",
        description="Streams the video through the ball detector (batched), smooths the track (RTS, cut at "
        "bounces), decodes hit events, estimates players when a pose backend is available and reconstructs "
        "the 3D ball. Stages whose inputs did not change are skipped on a re-run; files the pipeline did not "
        "write are never overwritten without --overwrite. Several inputs or a dataset folder (manifest.yaml) "
        "run through Lightning's predict loop (--devices/--strategy ddp spread clips over GPUs).",
    )
    p.add_argument("inputs", type=Path, nargs="+", metavar="VIDEO_OR_CLIP",
                   help="a video file, a clip folder (clip.yaml) or a dataset folder (manifest.yaml)")
    p.add_argument("--court", help="padel or tennis (or a court YAML); needed for a video, read from clip.yaml otherwise")
    p.add_argument("--camera", type=Path, help="camera.yaml of this video's camera")
    p.add_argument("--court-points", help="court_points.csv clicked on this video (calibrated here; floor points "
                   "suffice), or 'auto': find the court's lines automatically (refused when unsure)")
    p.add_argument("--start", type=float, help="seconds: process the video from here (a clip cut from a long match "
                   "is written into --out)")
    p.add_argument("--end", type=float, help="seconds: process the video up to here")
    p.add_argument("--mask", choices=["auto"], help="auto: hide static overlays (a scoreboard, a logo) from the "
                   "detector: writes mask: auto into clip.yaml; the boxes found go to mask_auto.yaml/.jpg to check")
    p.add_argument("--out", type=Path, help="output clip folder (a video: default runs/infer/<stem>; a clip: in "
                   "place); with several inputs, the parent folder of one clip folder each")
    p.add_argument("--detector", type=Path, help="ball-detector checkpoint (default: the shipped weights)")
    p.add_argument("--detector-model", choices=["wasb", "tracknetv2", "monotrack"], default="wasb",
                   help="architecture when the checkpoint does not name one (rally3d's files name it)")
    p.add_argument("--trust-checkpoint", action="store_true",
                   help="allow a detector checkpoint that holds pickled Python objects (unpickling runs code "
                   "stored in the file: only for files you trust); without it such a file is refused")
    p.add_argument("--events", type=Path, help="hit-event model file (default: the shipped model of the sport)")
    p.add_argument("--rally-only", action="store_true",
                   help="leave the events judged outside the point (the server's bounces before the serve, the ball "
                   "after it) out of events.csv; rally.yaml lists them with the point's start and end either way")
    p.add_argument("--pose", default="auto", help="pose backend: auto (MoveNet if installed), none, movenet, "
                   "rtmpose, rtmo")
    p.add_argument("--pose-model", type=Path, help="model file of the pose backend")
    from inference.players.sampling import parse_pose_every

    p.add_argument("--pose-every", type=parse_pose_every, default=0, metavar="N|auto",
                   help="pose every N-th frame, the tracker fills the frames between (default auto: about 15 "
                   "looks a second, every 2nd frame at 25-30 fps; 1: every frame)")
    p.add_argument("--method", default="joint", help="3D reconstruction method (default joint)")
    p.add_argument("--batch-size", type=int, default=1,
                   help="detector windows per forward pass (default 1: fastest on a CPU; raise it on a GPU)")
    p.add_argument("--step", type=int, default=3, help="detector window step in frames (default 3)")
    p.add_argument("--detector-backend", choices=["auto", "torch", "onnx", "onnx-int8"], default="auto",
                   help="auto (default): ONNX Runtime on the CPU where installed, else eager PyTorch; torch; onnx "
                   "(rally3d[onnx]); onnx-int8: the weights' int8 companion, ~2.5x faster detection that loses a few "
                   "%% of the weak detections (docs/detectors.md#int8)")
    p.add_argument("--detector-crop", choices=["auto", "off"], default="auto",
                   help="auto (default): the full frame only to find the ball, then a window around it; off")
    p.add_argument("--device", default="cpu", help="cpu or cuda (single clip)")
    p.add_argument("--only", help=f"comma-separated stages to run ({', '.join(STAGE_NAMES)}); the others are reused")
    p.add_argument("--overwrite", action="store_true", help="replace files the pipeline did not write (backed up)")
    p.add_argument("--reference", type=Path, help="clip with annotations / ground truth to score against "
                   "(default: the input clip when --out writes elsewhere)")
    p.add_argument("--split", help="with a dataset folder: only this split")
    p.add_argument("--accelerator", default="auto", help="several clips: Lightning accelerator (default auto)")
    p.add_argument("--devices", default="1", help="several clips: Lightning devices (default 1)")
    p.add_argument("--strategy", default="auto", help="several clips: Lightning strategy (e.g. ddp)")
    p.add_argument("--match", action="store_true",
                   help="a whole match: find the rallies in one pass (cuts, court views, quiet moments) and write "
                   "one clip folder per rally plus index.csv into --out; a re-run resumes (default for a video "
                   f"longer than {MATCH_ABOVE_S / 60:.0f} min)")
    p.add_argument("--rallies", help="--match: run only these rallies now, by their number in index.csv (3 or "
                   "1-3,7); the others keep their status")
    p.add_argument("--whole", action="store_true", help="a long video as one clip (no split into rallies)")
    p.add_argument("--min-rally", type=float, default=MatchParams.min_rally_s,
                   help=f"--match: court views shorter than this many seconds are no rally (default "
                   f"{MatchParams.min_rally_s:g})")
    p.add_argument("--max-rally", type=float, default=MatchParams.max_rally_s,
                   help="--match: a longer court view (a club camera) is split at its quietest moments (default "
                   f"{MatchParams.max_rally_s:g} s)")
    p.add_argument("--workers", help="several inputs (or a folder of videos): run them in N worker processes of a "
                   "local Dask cluster (auto: one per CPU core), one input per worker at a time")
    p.add_argument("--cluster", metavar="ADDRESS", help="send the inputs to a running Dask scheduler (tcp://HOST:8786) "
                   "whose workers may be on other machines; inputs and --out must be on a folder every machine sees "
                   "at the same path (docs/pipeline.md)")
    p.add_argument("--threads", type=int, default=1, help="--workers/--cluster: torch threads per worker (default 1)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def _config(args: argparse.Namespace):
    from .stages import PipelineConfig

    return PipelineConfig(detector=args.detector_model, detector_weights=args.detector,
                          trust_checkpoint=args.trust_checkpoint, step=args.step,
                          detector_backend=args.detector_backend, detector_crop=args.detector_crop,
                          batch_size=args.batch_size, events=args.events, rally_only=args.rally_only, pose=args.pose,
                          pose_model=args.pose_model, pose_every=args.pose_every, method=args.method, device=args.device,
                          overwrite=args.overwrite, progress=not args.no_progress,
                          auto_court=args.court_points == "auto")


def _court_points(args: argparse.Namespace) -> Path | None:
    """The --court-points file (None for ``auto`` or none)."""
    return None if args.court_points in (None, "auto") else Path(args.court_points)


def _expand(args: argparse.Namespace) -> list[tuple[Path, Path | None]]:
    """(input, output) per clip; dataset folders expand to their clips."""
    from inference.clipio import Manifest

    from .prepare import VIDEO_SUFFIXES

    items: list[tuple[Path, Path | None]] = []
    for path in args.inputs:
        if path.is_dir() and (path / "manifest.yaml").is_file():
            items += [(Path(c), None) for c in Manifest.load(path).paths(args.split)]
        elif path.is_dir() and not (path / "clip.yaml").is_file():
            videos = sorted(p for p in path.iterdir() if p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES)
            if not videos:
                raise ValueError(f"{path}: a folder with no clip.yaml, no manifest.yaml and no video file "
                                 f"({', '.join(sorted(VIDEO_SUFFIXES))}); give a video, a clip folder or a dataset")
            items += [(v, None) for v in videos]
        else:
            items.append((path, None))
    if len(items) > 1 and args.out is not None:
        items = [(src, args.out / (src.stem if src.is_file() else src.name)) for src, _ in items]
    elif args.out is not None:
        items = [(items[0][0], args.out)]
    return items


def _only_stages(text: str | None) -> set[str] | None:
    """The stages ``--only`` names (None: all); a former name (:data:`STAGE_ALIASES`) is taken with a note on
    stderr; ValueError for an unknown one."""
    if not text:
        return None
    names = set(text.split(","))
    for old in sorted(names & set(STAGE_ALIASES)):
        print(f"rally3d infer: note: stage '{old}' is now called '{STAGE_ALIASES[old]}' (the old name is "
              "deprecated)", file=sys.stderr)
    names = {STAGE_ALIASES.get(n, n) for n in names}
    unknown = sorted(names - set(STAGE_NAMES))
    if unknown:
        raise ValueError(f"unknown stages {unknown}; choose from {', '.join(STAGE_NAMES)}")
    return names


def run(args: argparse.Namespace) -> int:
    cfg = _config(args)
    items = _expand(args)
    if not items:
        raise ValueError("no clips to run (empty dataset or split)")
    only = _only_stages(args.only)
    if args.workers or args.cluster:
        return _run_distributed(items, cfg, args, only)
    if len(items) == 1:
        return _run_one(items[0], cfg, args, only)
    if args.start is not None or args.end is not None:
        raise ValueError("--start/--end cut one video; give a single input")
    if args.mask:
        raise ValueError("--mask auto takes a single input; for a dataset write 'mask: auto' in each clip.yaml")
    from .engine import predict_clips

    devices = int(args.devices) if str(args.devices).isdigit() else args.devices
    results = predict_clips(items, cfg, court=args.court, camera=args.camera, court_points=_court_points(args),
                            accelerator=args.accelerator, devices=devices, strategy=args.strategy)
    return _print_results(results, "clips")


def _print_results(results: list[dict], noun: str) -> int:
    """Each input's summary (its table or error) and the count complete; the exit code (1 if any is not)."""
    failed = 0
    for r in results:
        print(f"\n== {r['input']} → {r.get('clip', '-')}: {'ok' if r.get('ok') else 'INCOMPLETE'}")
        print(r.get("table") or r.get("error", ""))
        failed += not r.get("ok")
    print(f"\n{len(results) - failed}/{len(results)} {noun} complete")
    return 1 if failed else 0


def _run_distributed(items, cfg, args: argparse.Namespace, only: set[str] | None) -> int:
    """``--workers`` / ``--cluster``: every input a task of a Dask cluster (:mod:`.distributed`)."""
    import os
    from dataclasses import asdict

    from .distributed import ItemJob, run_items

    if args.start is not None or args.end is not None or args.mask or args.rallies:
        raise ValueError("--start/--end, --mask and --rallies take one input without --workers/--cluster")
    workers = None
    if args.workers:
        if args.cluster:
            raise ValueError("--workers starts a local cluster, --cluster uses a running one: give one of them")
        w = str(args.workers)
        if w != "auto" and (not w.isdigit() or int(w) < 1):
            raise ValueError(f"--workers {w!r}: a number of processes ≥ 1, or auto (one per CPU core)")
        workers = (os.cpu_count() or 1) if w == "auto" else int(w)
    params = asdict(MatchParams(min_rally_s=args.min_rally, max_rally_s=args.max_rally))
    jobs = [ItemJob(str(src), None if dest is None else str(dest), args.court,
                    None if args.camera is None else str(args.camera),
                    None if _court_points(args) is None else str(_court_points(args)),
                    None if only is None else tuple(sorted(only)),
                    True if args.match else (False if args.whole else None), params, max(0, int(args.threads)))
            for src, dest in items]
    return _print_results(run_items(jobs, cfg, workers=workers, address=args.cluster), "inputs")


def _is_match(source: Path, args: argparse.Namespace) -> bool:
    """A video to split into rallies: ``--match``, or a video longer than :data:`MATCH_ABOVE_S` without
    ``--whole``/``--start``/``--end`` (which say: one clip)."""
    if getattr(args, "whole", False) or args.start is not None or args.end is not None:
        if getattr(args, "match", False):
            raise ValueError("--match splits a whole video into rallies; leave out --whole, --start and --end")
        return False
    from .match import is_long_video, is_video_file

    if not is_video_file(source):
        if getattr(args, "match", False):
            raise ValueError(f"{source}: --match takes a video file (a clip folder is one rally already)")
        return False
    if getattr(args, "match", False):
        return True
    if is_long_video(source, MATCH_ABOVE_S):
        print(f"rally3d infer: {source} is longer than {MATCH_ABOVE_S / 60:g} min: treated as a match (split into "
              "rallies); --whole runs it as one clip", file=sys.stderr)
        return True
    return False


def _run_one(item: tuple[Path, Path | None], cfg, args: argparse.Namespace,
             only: set[str] | None = None) -> int:
    from inference.clipio import Clip

    from .prepare import Cut, prepare, request_auto_mask, video_notes
    from .run import run_pipeline
    from .score import score

    source, out = item
    if _is_match(source, args):
        from .match import parse_rallies, run_match

        if args.mask:
            raise ValueError("--mask auto takes one clip; a match's rallies are masked with 'mask: auto' in each "
                             "clip.yaml, or run the rally folders again with --mask auto")
        params = MatchParams(min_rally_s=args.min_rally, max_rally_s=args.max_rally)
        return run_match(source, out if out is not None else Path("runs/infer") / source.stem, args.court, cfg,
                         camera=args.camera, court_points=_court_points(args), params=params, only=only,
                         rallies=parse_rallies(args.rallies))
    if getattr(args, "rallies", None):
        raise ValueError("--rallies picks rallies of a match: add --match (a video file)")
    prepared = prepare(source, out, args.court, args.camera, _court_points(args), Cut(args.start, args.end))
    clip = prepared.clip
    if args.mask == "auto":
        clip = request_auto_mask(clip)
    print(f"rally3d infer: {source} → {clip.root} ({clip.info.width}×{clip.info.height}, {clip.info.fps:g} fps, "
          f"{clip.n_frames} frames)")
    for note in video_notes(clip.root if "cut" not in clip.info.extra else source):
        print(f"rally3d infer: note: {note}")
    report = run_pipeline(clip, cfg, only=only)
    print()
    print(report.table())
    reference = Clip(args.reference) if args.reference else prepared.reference
    if reference is not None:
        lines = score(clip, reference).lines()
        if lines:
            print(f"\nagainst {reference.root}:")
            print("\n".join("  " + line for line in lines))
    if report.ok:
        print(f"\nwrote {clip.root}  (review it: rally3d review {clip.root})")
        return 0
    bad = [s for s in report.stages if s.status in ("failed", "partial", "skipped", "blocked") and s.name != "players"]
    print(f"\nincomplete: {', '.join(f'{s.name} {s.status}' for s in bad)}; partial results kept in {clip.root}",
          file=sys.stderr)
    return 1
