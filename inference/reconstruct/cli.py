"""``rally3d reconstruct`` and ``rally3d eval-3d``."""
from __future__ import annotations

import argparse
from pathlib import Path


def register_reconstruct(sub: argparse._SubParsersAction) -> None:
    from .api import DEFAULT_METHOD, METHOD_NAMES

    p = sub.add_parser(
        "reconstruct",
        help="reconstruct the ball's 3D path of a clip (writes ball_3d.csv and segments.json)",
        description="Reads camera.yaml (P alone suffices), ball.csv, events.csv and players.csv if present; "
        "fits the flights between events and writes ball_3d.csv (every frame from the first to the last "
        "event, with 1-σ uncertainty) and segments.json (contacts, planes, launch velocity, spin, drag, "
        "reprojection RMS, speeds, net clearance, bounce positions).",
    )
    p.add_argument("clip", type=Path)
    p.add_argument("--method", choices=METHOD_NAMES, default=DEFAULT_METHOD,
                   help=f"reconstruction method (default {DEFAULT_METHOD})")
    p.add_argument("--gt-camera", action="store_true", help="use gt/camera.yaml instead of camera.yaml")
    p.set_defaults(func=run_reconstruct)


def run_reconstruct(args: argparse.Namespace) -> int:
    from inference.clipio import Clip

    from .api import reconstruct
    from .observations import Observations

    clip = Clip(args.clip)
    camera = clip.read_camera(gt=args.gt_camera)
    clip.check_camera(camera, clip.root / ("gt" if args.gt_camera else "") / "camera.yaml")
    from inference.camera.calibration import require_court_view
    from inference.court import load_court

    require_court_view(camera, load_court(clip.court_path()), clip.root / ("gt" if args.gt_camera else "") / "camera.yaml")
    obs = Observations.from_clip(clip, camera=camera)
    if not len(obs.event_frames):
        raise ValueError(f"{clip.events_path}: needs at least one event (a bounce or a hit) to anchor the flight")
    fit = reconstruct(obs, args.method)
    fit.save(clip)
    print(f"{clip.root.name}: method {fit.method}, {len(fit.segments)} flights, {fit.n_frames} frames in "
          f"{fit.seconds * 1e3:.0f} ms")
    print(f"{'flight':>6} {'frames':>9} {'from':>12} {'to':>12} {'launch km/h':>11} {'net m':>6} {'RMS px':>7}")
    for s in fit.segments:
        seg = s.segment
        if not s.ok:
            print(f"{seg.index:>6} {seg.start:>4}-{seg.end:<4} not reconstructed: {s.reason}")
            continue
        d = s.to_dict(fit.fps)
        net = d.get("net_clearance_m")
        print(f"{seg.index:>6} {seg.start:>4}-{seg.end:<4} {seg.start_event or '(free end)':>12} "
              f"{seg.end_event or '(free end)':>12} "
              f"{d.get('launch_speed_kmh', float('nan')):>11.1f} {'' if net is None else f'{net:.2f}':>6} "
              f"{s.reproj_rms_px:>7.2f}")
    pl = fit.extra.get("plausibility", {})
    if pl:
        verdict = "plausible" if pl["plausible"] else f"NOT plausible ({'; '.join(pl.get('not_plausible_because', []))})"
        print(f"plausibility: {verdict} — {pl['reconstructed']}/{pl['flights']} flights reconstructed, "
              f"{pl['frames_inside_court']:.1%} of frames inside the court, {pl['contacts_below_floor']} contacts "
              f"below the floor")
    print(f"wrote {clip.ball_3d_path} and {clip.segments_path}")
    return 0


def register_eval(sub: argparse._SubParsersAction) -> None:
    from .api import METHOD_NAMES

    p = sub.add_parser(
        "eval-3d",
        help="compare reconstructions with gt/ball_3d.csv (MRE, MedRE, MAE, MedAE, frames/s per method)",
        description="For clips with ground truth (synthetic, multi-camera): prepares the inputs (2D noise, "
        "event-frame shifts, players), runs each method and prints a Markdown table.",
    )
    p.add_argument("clips", type=Path, nargs="+", help="clip folders, or dataset folders with manifest.yaml")
    p.add_argument("--methods", default=",".join(METHOD_NAMES), help="comma-separated (default: all)")
    p.add_argument("--noise", type=float, default=2.0, help="σ of Gaussian 2D noise in px (default 2)")
    p.add_argument("--event-shift", type=int, default=0, help="shift events by up to ±k frames (default 0)")
    p.add_argument("--players", choices=["gt", "clip", "none"], default="gt",
                   help="players' court positions: gt/players.csv (default), the clip's players.csv, or none")
    p.add_argument("--camera", choices=["gt", "clip"], default="gt", help="gt/camera.yaml (default) or camera.yaml")
    p.add_argument("--split", help="with a dataset folder: only this split (e.g. test)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--sensitivity", action="store_true",
                   help="also the default method's error vs 2D noise (0, 2, 5 px) and event shifts (±1, ±2)")
    p.set_defaults(func=run_eval)


def clip_list(paths: list[Path], split: str | None = None) -> list:
    from inference.clipio import Clip, Manifest

    clips = []
    for p in paths:
        if (p / "manifest.yaml").is_file():
            clips += [Clip(c) for c in Manifest.load(p).paths(split)]
        else:
            clips.append(Clip(p))
    return clips


def run_eval(args: argparse.Namespace) -> int:
    from .api import METHOD_NAMES, methods
    from .evaluate import Setting, evaluate, format_table

    clips = clip_list(args.clips, args.split)
    table = methods()
    chosen = [m.strip() for m in args.methods.split(",") if m.strip()]
    unknown = [m for m in chosen if m not in table]
    if unknown:
        raise ValueError(f"unknown methods {unknown}; choose from {', '.join(METHOD_NAMES)}")
    setting = Setting(args.noise, args.event_shift, args.players, args.camera, args.seed)
    rows = evaluate(clips, {m: table[m] for m in chosen}, setting)
    print(format_table(rows, f"{len(clips)} clips; {setting.label()}"))
    for m, r in rows.items():
        if r["failed"]:
            print(f"{m}: {len(r['failed'])} flights not reconstructed, e.g. {r['failed'][0]}")
    if args.sensitivity:
        print()
        print(sensitivity_table(clips, table["joint"], setting))
    return 0


def sensitivity_table(clips, fn, base) -> str:
    from dataclasses import replace

    from .evaluate import evaluate

    lines = ["| default method | MAE m | MedAE m | MRE px |", "|---|---|---|---|"]
    variants = [("2D noise 0 px", replace(base, noise_px=0.0, event_shift=0)),
                ("2D noise 2 px", replace(base, noise_px=2.0, event_shift=0)),
                ("2D noise 5 px", replace(base, noise_px=5.0, event_shift=0)),
                ("events ±1 frame (2 px noise)", replace(base, noise_px=2.0, event_shift=1)),
                ("events ±2 frames (2 px noise)", replace(base, noise_px=2.0, event_shift=2))]
    for label, s in variants:
        r = evaluate(clips, {"joint": fn}, s)["joint"]
        lines.append(f"| {label} | {r['MAE_m']:.3f} | {r['MedAE_m']:.3f} | {r['MRE_px']:.2f} |")
    return "\n".join(lines)
