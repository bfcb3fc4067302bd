"""Export a trained detector as the shipped weights (public WASB-SBDT format) with its model card.

    .venv/bin/python -m training.detection.ship CKPT --name wasb --card-notes "..."
"""
from __future__ import annotations

import argparse
import hashlib
from pathlib import Path

from inference.detection.detect import WEIGHTS_DIR
from inference.models.checkpoint import load_weights, save_wasb_checkpoint
from inference.models.registry import build_model


def ship(ckpt: Path, name: str, card: str, out_dir: Path = WEIGHTS_DIR) -> Path:
    model = build_model(name)
    info = load_weights(model, ckpt)
    path = save_wasb_checkpoint(model, out_dir / f"{name}_padel.pth.tar", epoch=int(info.get("meta", {}).get("epoch", 0)))
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    (out_dir / "MODEL_CARD.md").write_text(card.replace("{sha256}", digest).replace("{file}", path.name))
    return path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ckpt", type=Path)
    ap.add_argument("--name", default="wasb")
    ap.add_argument("--card", type=Path, required=True, help="model card (Markdown; {sha256} and {file} are filled in)")
    a = ap.parse_args(argv)
    path = ship(a.ckpt, a.name, a.card.read_text())
    print(f"wrote {path} and {path.parent / 'MODEL_CARD.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
