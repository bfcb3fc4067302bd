"""The embedded sample regenerates bit for bit from its documented command."""
from __future__ import annotations

from pathlib import Path

from training.synth.sample import SAMPLE_CLIPS, make_sample

SAMPLE = Path(__file__).resolve().parents[3] / "datasets" / "sample"


def test_sample_regenerates_bit_for_bit(tmp_path):
    make_sample(tmp_path)
    for clip in SAMPLE_CLIPS:
        committed = sorted(p.relative_to(SAMPLE) for p in (SAMPLE / clip.name).rglob("*") if p.is_file())
        fresh = sorted(p.relative_to(tmp_path) for p in (tmp_path / clip.name).rglob("*") if p.is_file())
        assert committed == fresh
        for rel in committed:
            assert (SAMPLE / rel).read_bytes() == (tmp_path / rel).read_bytes(), rel
    assert (SAMPLE / "manifest.yaml").read_text() == (tmp_path / "manifest.yaml").read_text()
