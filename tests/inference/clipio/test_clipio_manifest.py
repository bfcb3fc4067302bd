"""Dataset manifests: round trip, deterministic splits, grouped splits, errors."""
from __future__ import annotations

import pytest

from inference.clipio import ClipInfo, FormatError, Manifest, ManifestEntry, split_of, write_clip_yaml


def make_clips(root, names):
    for n in names:
        write_clip_yaml(root / n / "clip.yaml", ClipInfo("padel", 30, 1280, 720, "video.mp4"))


def test_from_folder_round_trip(tmp_path):
    names = [f"clip_{i:03d}" for i in range(40)]
    make_clips(tmp_path, names)
    m = Manifest.from_folder(tmp_path)
    assert [c.path for c in m.clips] == names
    counts = m.counts()
    assert sum(counts.values()) == 40 and counts["train"] > counts["val"] > 0
    m.sport = "padel"
    m.save()
    back = Manifest.load(tmp_path)
    assert back.clips == m.clips and back.sport == "padel"
    assert back.paths("val")[0].is_dir()


def test_split_is_stable_and_grouped(tmp_path):
    assert split_of("match7") == split_of("match7")
    names = [f"match{m}_rally{r}" for m in range(6) for r in range(5)]
    make_clips(tmp_path, names)
    m = Manifest.from_folder(tmp_path, group_key=lambda n: n.split("_")[0])
    by_match = {}
    for c in m.clips:
        by_match.setdefault(c.path.split("_")[0], set()).add(c.split)
    assert all(len(s) == 1 for s in by_match.values())


def test_bad_manifests(tmp_path):
    make_clips(tmp_path, ["a"])
    (tmp_path / "manifest.yaml").write_text("clips:\n  - {path: a, split: training}\n")
    with pytest.raises(FormatError, match="split must be one of"):
        Manifest.load(tmp_path)
    (tmp_path / "manifest.yaml").write_text("clips:\n  - {path: b, split: train}\n")
    with pytest.raises(FormatError, match="without clip.yaml"):
        Manifest.load(tmp_path)
    (tmp_path / "manifest.yaml").write_text("name: x\n")
    with pytest.raises(FormatError, match="clips"):
        Manifest.load(tmp_path)
    with pytest.raises(ValueError):
        ManifestEntry("a", "dev")


def test_clips_listed_by_name(tmp_path):
    """Another tool's manifest names its clip folders with `name:` (or bare strings)."""
    from inference.clipio import Manifest

    for name in ("rally_a", "rally_b", "rally_c"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "clip.yaml").write_text("sport: padel\nfps: 25\nwidth: 640\nheight: 360\nvideo: v.mp4\n")
    (tmp_path / "manifest.yaml").write_text(
        "clips:\n  - {name: rally_a, split: test}\n  - name: rally_b\n  - rally_c\n")
    m = Manifest.load(tmp_path)
    assert [c.path for c in m.clips] == ["rally_a", "rally_b", "rally_c"]
    assert [c.split for c in m.clips] == ["test", "train", "train"]
    (tmp_path / "manifest.yaml").write_text("clips:\n  - {split: test}\n")
    with pytest.raises(Exception, match="needs a `path` \\(or `name`\\)"):
        Manifest.load(tmp_path)
