"""``rally3d review CLIP``: serve the 3D review (prints the URL, serves until Ctrl-C), or ``--export DIR``."""
from __future__ import annotations

import argparse
import math
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "review",
        help="3D review of a reconstructed clip in the browser (viser), or export its replay and shot table",
        description="Shows the court, the reconstructed ball with its trail, contacts with their line calls, "
        "the players, a timeline with play/pause/speed and event marks, camera presets, and the video frame "
        "with the reprojected ball and court. Needs camera.yaml, ball_3d.csv (rally3d reconstruct / infer) "
        "and events.csv; uses segments.json, ball.csv, players.csv when present.",
    )
    p.add_argument("clip", type=Path, help="clip folder")
    p.add_argument("--host", default="127.0.0.1", help="address to listen on (0.0.0.0: every interface)")
    p.add_argument("--port", type=int, default=8080, help="port (default 8080; the next free one if taken)")
    p.add_argument("--export", type=Path, metavar="DIR",
                   help="write DIR/replay.viser, DIR/replay.html and DIR/shots.csv, print the shots and exit")
    p.add_argument("--stride", type=int, default=1, help="--export: record every N-th frame (default 1)")
    p.add_argument("--no-serve-rules", action="store_true",
                   help="judge the first hit as a rally shot, not a serve (clips that start mid-rally)")
    p.set_defaults(func=run)


def shots_table(analysis) -> str:
    """The shots as a console table, after the clip's 3D status (:meth:`RallyAnalysis.status_lines`: a
    ``3D NOT plausible`` / ``NOT judged`` banner first when it applies, and the rally's coverage). A shot
    without trustworthy 3D shows no figure and no call, only ``no 3D: <why>``."""
    from .shots import call_text

    def f(v, nd=1):
        return "" if v is None or not math.isfinite(v) else f"{v:.{nd}f}"

    out = [*analysis.status_lines(),
           f"{'shot':>4} {'team':>4} {'hit':>5} {'km/h':>6} {'net m':>6} {'bounce (m)':>14} {'call':>5} "
           f"{'line cm':>8} {'σ cm':>5}  call / reason"]
    for s in analysis.shots:
        b = s.first_bounce if s.has_3d else None
        xy = "" if b is None or not b.judged else f"({b.xy[0]:.2f},{b.xy[1]:.2f})"
        sigma = "" if b is None or not b.judged else (f(b.sigma_cm) or "?")
        text = f"{call_text(b)}; {s.reason}" if b is not None and b.judged else s.reason
        out.append(f"{s.index:>4} {s.team:>4} {s.hit.frame:>5} {f(s.launch_speed_kmh):>6} "
                   f"{f(s.net_clearance_m, 2):>6} {xy:>14} {s.verdict:>5} "
                   f"{'' if b is None else f(b.distance_cm, 0):>8} {sigma:>5}  {text}")
    return "\n".join(out)


def run(args: argparse.Namespace) -> int:
    from .data import ReviewData

    data = ReviewData.load(args.clip, first_hit_is_serve=not args.no_serve_rules)
    print(shots_table(data.analysis))  # the 3D status first: the banner is the first line printed
    print(f"{args.clip}: {data.summary()['reconstructed']} reconstructed frames, {len(data.analysis.shots)} shots")
    if args.export is not None:
        from .export import export_review

        res = export_review(data, args.export, stride=args.stride)
        print(f"wrote {res.replay} ({res.n_steps} steps), {res.html} and {res.shots_csv}")
        print(f"play it without Python: open {res.html} in a browser, or serve {res.replay.parent} with viser's "
              "client (index.html?playbackPath=replay.viser)")
        return 0
    from .app import ReviewApp

    app = ReviewApp(data, host=args.host, port=args.port)
    url = app.start()
    print(f"rally3d review: open {url}  (Ctrl-C to stop)", flush=True)
    app.serve_forever()
    return 0
