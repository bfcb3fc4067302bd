"""Real ball tracks beside simulated ones: what a real tracker (and a hand annotation) does around the
events, measured the same way on simulated rallies degraded as the shipped event tagger was trained, and as
the setting fitted from the real figures (:mod:`training.events.stats.real_stats`). Prints one table per sport and
writes the fitted ``data.degrade`` settings (``conf/data/degrade/real_<sport>_broadcast.yaml``).

    .venv/bin/python bench/bench_real_track_stats.py [--sims 60] [--no-write] [--sports tennis,padel]

Real material (measurement only, read in place; skips with one line without it): ``$RALLY3D_REAL`` or the
development setup's ``shared/real`` beside the checkout — tennis: 250 points of a real final (a real
tracker's ``ball.csv``, hand-made hit/bounce labels, 50 fps); padel: a hand-annotated ball on a real
broadcast with the players' stroke windows (25 fps rows; a racket contact is taken at each window's middle,
so the padel figures are for racket hits and hand-labelled direction changes only).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

HEADER = """# Fitted from real broadcast tracks (bench/bench_real_track_stats.py, {what}): the gaps of a real tracker around
# the near and far players' hits and the bounces, the other misses, the wrong positions and the jitter (the real
# tracks are unsmoothed: p_smooth 0); what it cannot measure (clean clips) is the shipped tagger's setting.
# Regenerate with its command line.
# Use as: python train.py +experiment=tagger_{sport}_players +data/degrade=real_{sport}_broadcast
"""


def real_tennis(root: Path):
    from inference.clipio import Clip

    out = []
    for d in sorted((root / "tennis_events_rg2025_dev").iterdir()):
        c = Clip(d)
        ev = c.read_events()
        if len(ev):
            out.append((c.read_ball(), ev, c.info.fps, c.info.width, c.info.height))
    return out


def real_padel(root: Path, fps: float = 25.0):
    """The hand-annotated padel broadcast as clips (one per point, one frame a CSV row: bench_real's reading
    of the file), racket hits at the middle of each stroke window, near/far by the lower/upper team."""
    from bench_real import padel_points, padel_strokes, read_wpt  # bench/ is the script's folder

    from inference.clipio import BallTrack, HitEvents

    rows = read_wpt(root / "padel_tracks_wpt2022_dev" / "wpt2022_master_final_women_frames_0-9999.csv")
    strokes, _ = padel_strokes(rows)
    W, H = 1920, 1080
    x = np.array([float(r["ball_center_x"]) if r["ball_center_x"] else np.nan for r in rows])
    y = np.array([float(r["ball_center_y"]) if r["ball_center_y"] else np.nan for r in rows])
    out = []
    for a, b in padel_points(rows, strokes, int(0.4 * fps), int(1.0 * fps)):
        n = b - a
        seen = np.isfinite(x[a:b])
        xy = np.stack([np.clip(x[a:b] / W, 0, 1), np.clip(y[a:b] / H, 0, 1)], axis=1)
        xy[~seen] = np.nan
        track = BallTrack(np.arange(n), seen.astype(np.int8), xy)
        hits = sorted({((s.start + s.end) // 2 - a, f"player_{s.side}") for s in strokes
                       if a <= s.start < b and s.side in ("near", "far")})
        if hits:
            out.append((track, HitEvents([f for f, _ in hits], [c for _, c in hits]), fps, W, H))
    return out


# the view of the real material: the padel track is a broadcast (high behind the glass, high lobs leave the
# picture's top); the tennis points and the default tennis camera are both broadcasts
REAL_VIEW = {"tennis": "tennis_broadcast", "padel": "padel_broadcast"}
#: a tour final's main camera (long lens far behind the baseline), the view of the real tennis points
TOUR_VIEW = "tennis_tv"


def simulated(clips, seed: int, degrade: dict | None):
    """``clips`` (:class:`SimClip`) as ``measure`` takes them: degraded by ``degrade`` (None: the clean track)."""
    from training.events.synthetic.degrade import DegradeConfig, degrade_all

    tracks = degrade_all(clips, seed, DegradeConfig.from_dict(degrade)) if degrade else [c.ball for c in clips]
    return [(t, c.events, c.fps, c.width, c.height) for t, c in zip(tracks, clips)]


def experiment_degrade(sport: str) -> dict:
    """The ``data.degrade`` of the shipped tagger's experiment (what it was trained on)."""
    import yaml

    cfg = yaml.safe_load((ROOT / "conf" / "experiment" / f"tagger_{sport}_players.yaml").read_text())
    return dict(cfg["data"]["degrade"])


def row(name: str, s: dict) -> str:
    def cls(c):
        d = s[c]
        return f"{d['hidden']:.2f} / {d['gap_s'][1]:.2f} ({d['gap_s'][0]:.2f}–{d['gap_s'][3]:.2f})" if d["gap_s"] else "–"

    return (f"| {name} | {cls('player_near')} | {cls('player_far')} | {cls('serve_far')} | {cls('ground')} | "
            f"{s['other_runs_per_s']:.2f} / {s['other_runs_s'][1] if s['other_runs_s'] else float('nan'):.2f} | "
            f"{s['other_miss_share']:.2f} | {s['jitter_px']} | {s['top_gap_share']} / {s['top_frame_share']} / {s['top_gap_s']} | "
            f"{' / '.join(f'{q:.2f}' for q in s['serve_flight_s']) if s['serve_flight_s'] else '–'} | "
            f"{' / '.join(f'{q:.2f}' for q in s['shot_flight_s']) if s.get('shot_flight_s') else '–'} | "
            f"{s.get('outlier_share', '–')} | {frame(s)} |")


def frame(s: dict) -> str:
    """Where the picture shows the far hits, the bounces and the near hits (median image row) and how fast the
    ball leaves the far and the near hits (px per 1/50 s, 1080 rows): the camera's framing and lens, the pace."""
    def med(c):
        r = s[c].get("row")
        return f"{r[1]:.2f}" if r else "–"

    def spd(c):
        v = s[c].get("speed_after")
        return f"{v:.1f}" if v is not None else "–"

    return (f"{med('player_far')} / {med('ground')} / {med('player_near')}; "
            f"{spd('player_far')} / {spd('player_near')}")


def main(argv=None) -> int:
    import yaml

    from bench_real import real_root
    from training.events.stats.real_stats import degrade_from, measure, top_crop_for
    from synth.generate import DEFAULT_CAMERA

    ap = argparse.ArgumentParser()
    ap.add_argument("--sims", type=int, default=60, help="simulated rallies per sport and setting")
    ap.add_argument("--seed", type=int, default=11)
    ap.add_argument("--no-write", action="store_true", help="print only; do not write conf/data/degrade/*.yaml")
    ap.add_argument("--sports", default="tennis,padel", help="comma-separated: tennis, padel")
    args = ap.parse_args(argv)
    root = real_root()
    if not root.is_dir():
        print(f"bench_real_track_stats: no real material at {root} (set RALLY3D_REAL): skipped")
        return 0
    t0 = time.process_time()
    cols = ("| tracks | near hits: hidden / gap s median (25–90 %) | far hits (not serves) | far serves | bounces | "
            "other misses per s / median s | other-miss share | jitter px | gaps above the picture: share of gaps / "
            "of frames / median s | serve → bounce s (10 / 50 / 90 %) | rally shot → bounce s (10 / 50 / 90 %) | "
            "wrong positions (> 15 px off) | image row of far hit / bounce / near hit; px per 1/50 s after a far / "
            "near hit |")
    wanted = set(args.sports.split(","))
    for sport, read in (("tennis", real_tennis), ("padel", real_padel)):
        if sport not in wanted:
            continue
        real = measure(read(root))
        base = experiment_degrade(sport)
        from training.events.synthetic.simulate import simulate_clips

        cache = ROOT / "runs" / "events_cache"
        sims = simulate_clips(sport, args.sims, args.seed, cache, progress=False)
        # the training camera's own share of frames above the picture; the crop makes up only the rest
        clean = measure(simulated(sims, args.seed, None))
        crop = top_crop_for([c.ball for c in sims], max(0.0, real["top_frame_share"] - clean["top_frame_share"]))
        # both real materials are unsmoothed (a tracker's raw output; a hand annotation)
        fitted = degrade_from(real, base, top_crop=crop, smoothed=False)
        shipped = measure(simulated(sims, args.seed, base))
        refit = measure(simulated(sims, args.seed, fitted))
        view = None
        if REAL_VIEW[sport] != DEFAULT_CAMERA[sport]:
            view = measure(simulated(simulate_clips(sport, args.sims, args.seed, cache, progress=False,
                                                    camera=REAL_VIEW[sport]), args.seed, None))
        print(f"\n## {sport}: {real['clips']} real clips, {args.sims} simulated rallies per setting\n")
        print(cols)
        print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
        print(row("real", real))
        if view is not None:
            print(row(f"simulated, clean, the real material's view ({REAL_VIEW[sport]})", view))
        print(row(f"simulated, clean, the training camera ({DEFAULT_CAMERA[sport]})", clean))
        if sport == "tennis":  # the tour pace (synth.rally.TENNIS_TOUR): a final's rally shots, as broadcast
            tour = simulate_clips(sport, args.sims, args.seed, cache, progress=False, pace="tour")
            print(row("simulated, clean, the training camera, tour pace", measure(simulated(tour, args.seed, None))))
            tv = simulate_clips(sport, args.sims, args.seed, cache, progress=False, pace="tour", camera=TOUR_VIEW)
            print(row(f"simulated, clean, tour pace through a tour broadcast's camera ({TOUR_VIEW})",
                      measure(simulated(tv, args.seed, None))))
        print(row("simulated, the shipped tagger's degradation", shipped))
        print(row("simulated, fitted to the real tracks", refit))
        if not args.no_write:
            path = ROOT / "conf" / "data" / "degrade" / f"real_{sport}_broadcast.yaml"
            head = HEADER.format(what=f"{real['clips']} real clips", sport=sport)
            body = {**fitted, "measured": {k: v for k, v in real.items()}}
            path.write_text(head + yaml.safe_dump(body, sort_keys=False, default_flow_style=None))
            print(f"\nwrote {path.relative_to(ROOT)}")
    print(f"\nCPU {time.process_time() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
