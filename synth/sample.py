"""The embedded sample under ``datasets/sample/``: small synthetic clips for the demo and the tests.

Regenerate it bit for bit (same package versions, see constraints.txt) with::

    make sample        # = .venv/bin/python -m synth.sample datasets/sample
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from inference.clipio import Manifest, ManifestEntry

from .generate import SynthConfig, generate_clip


@dataclass(frozen=True)
class SampleClip:
    name: str
    seed: int
    config: SynthConfig


SAMPLE_CLIPS = (
    SampleClip("padel_sample", 7, SynthConfig(sport="padel", randomise_camera=False, width=1280, height=720,
                                             fps=30.0, codec="h264", crf=26, max_frames=240)),
    SampleClip("tennis_sample", 27, SynthConfig(sport="tennis", randomise_camera=False, width=1280, height=720,
                                              fps=30.0, codec="h264", crf=26, max_frames=180)),
)


def make_sample(out: str | Path) -> Manifest:
    """Write the sample clips and a manifest (all in the test split) into ``out``."""
    out = Path(out)
    for c in SAMPLE_CLIPS:
        generate_clip(out / c.name, c.seed, c.config)
    manifest = Manifest(out, [ManifestEntry(c.name, "test") for c in SAMPLE_CLIPS], name="sample",
                        source="python -m synth.sample datasets/sample")
    manifest.save()
    return manifest


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description="Write the embedded sample clips.")
    ap.add_argument("out", type=Path, nargs="?", default=Path("datasets/sample"))
    args = ap.parse_args(argv)
    manifest = make_sample(args.out)
    size = sum(p.stat().st_size for p in args.out.rglob("*") if p.is_file())
    print(f"wrote {[c.path for c in manifest.clips]} to {args.out} ({size / 1e6:.2f} MB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
