"""One evaluation table for several trained ball detectors (the README's three-model table).

    .venv/bin/python -m training.detection.compare data/synth_padel \\
        wasb_padel=inference/weights/wasb_padel.pth.tar \\
        tracknetv2_padel=runs/tracknetv2/checkpoints/best.ckpt monotrack_padel=runs/monotrack/checkpoints/best.ckpt \\
        --out docs/detectors_padel_table.md

Each ``EXPERIMENT=CHECKPOINT`` is composed like ``python eval.py +experiment=EXPERIMENT ckpt_path=CHECKPOINT
data.root=ROOT split=SPLIT`` and run over whole clips at full resolution (windows → heatmaps → candidates →
our tracker, and WASB-SBDT's max-score baseline); the rows of all models are printed as one table per τ
(4 px in original-frame pixels, 10 px at 1280×720) and optionally written to a Markdown file.
"""
from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

from inference.detection.metrics import TableRow, format_table

ROOT = Path(__file__).resolve().parents[2]


def compose_eval(experiment: str, ckpt: str, root: str, split: str, extra: list[str] = ()):
    """The config ``eval.py +experiment=… ckpt_path=… data.root=… split=…`` would run."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    if not (ROOT / "conf" / "experiment" / f"{experiment}.yaml").is_file():
        known = sorted(p.stem for p in (ROOT / "conf" / "experiment").glob("*.yaml"))
        raise SystemExit(f"unknown experiment {experiment!r}: choose one of {', '.join(known)}")
    if not Path(ckpt).is_file():
        raise SystemExit(f"checkpoint {ckpt} not found (for {experiment})")
    os.environ.setdefault("PROJECT_ROOT", str(ROOT))
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return compose(config_name="eval", overrides=[f"+experiment={experiment}", f"ckpt_path={ckpt}",
                                                      f"data.root={root}", f"split={split}", *extra])


def compare(models: dict[str, str], root: str, split: str = "test", extra: list[str] = ()) -> dict[str, list[TableRow]]:
    """Evaluate each ``experiment → checkpoint`` and merge their rows per τ setting ("tau4", "tau10")."""
    from training.run import evaluate_detector

    merged: dict[str, list[TableRow]] = {}
    for experiment, ckpt in models.items():
        result = evaluate_detector(compose_eval(experiment, ckpt, root, split, extra))
        for key, rows in result.tables.items():
            merged.setdefault(key, []).extend(
                TableRow(f"{experiment.split('_')[0]} + {row.name.split(' + ', 1)[1]}", row.report, row.fps)
                for row in rows)
    return merged


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("root", help="dataset folder with manifest.yaml")
    ap.add_argument("models", nargs="+", metavar="EXPERIMENT=CHECKPOINT")
    ap.add_argument("--split", default="test")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                    help="extra Hydra override for every model (e.g. batch_size=1)")
    ap.add_argument("--out", type=Path, help="also write the tables to this Markdown file")
    a = ap.parse_args(argv)
    models = {}
    for item in a.models:
        experiment, sep, ckpt = item.partition("=")
        if not sep or not ckpt:
            ap.error(f"{item!r}: write EXPERIMENT=CHECKPOINT, e.g. wasb_padel=inference/weights/wasb_padel.pth.tar")
        models[experiment] = ckpt
    tables = compare(models, a.root, a.split, a.set)
    text = "\n\n".join(format_table(rows, counts=True) for rows in tables.values())
    print(text)
    if a.out:
        command = " ".join(shlex.quote(x) for x in [".venv/bin/python", "-m", "training.detection.compare",
                                                     *(argv if argv is not None else sys.argv[1:])])
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(f"# Ball detectors on {a.root} ({a.split} split)\n\nRegenerate: `{command}`\n\n{text}\n")
        print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
