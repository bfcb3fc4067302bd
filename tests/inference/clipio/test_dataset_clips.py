"""The clips of a dataset (a clip folder, a manifest or a folder of clip folders), every unusable manifest
entry reported at once, and ``rally3d check`` naming the file of a reader's plain ValueError."""
from __future__ import annotations

import pytest

from inference.cli import main
from inference.clipio import FormatError, Manifest
from inference.clipio.manifest import dataset_clips

CLIP_YAML = "sport: padel\nfps: 30\nwidth: 64\nheight: 48\nvideo: video.mp4\nn_frames: 4\n"


def clip(folder) -> None:
    folder.mkdir(parents=True)
    (folder / "clip.yaml").write_text(CLIP_YAML)


def test_every_unusable_manifest_entry_is_reported_and_the_rest_kept(tmp_path):
    clip(tmp_path / "a")
    clip(tmp_path / "b")
    (tmp_path / "manifest.yaml").write_text("clips:\n  - {path: a, split: train}\n  - {path: gone, split: val}\n"
                                            "  - {path: b, split: later}\n  - {split: test}\n  - b\n")
    with pytest.raises(FormatError, match="clip entry 2 \\(b\\): split must be one of"):
        Manifest.load(tmp_path)  # without skipped: the first problem raises, as before
    skipped: list[FormatError] = []
    m = Manifest.load(tmp_path, skipped=skipped)
    assert [(c.path, c.split) for c in m.clips] == [("a", "train"), ("b", "train")]
    assert [e.problem for e in skipped] == [
        "clip entry 2 (b): split must be one of ('train', 'val', 'test'), got 'later'",
        "clip entry 3 needs a `path` (or `name`): the clip folder",
        f"clip folder gone has no clip.yaml (looked in {tmp_path / 'gone'})"]
    assert all(e.fix for e in skipped)


def test_dataset_clips_of_each_form(tmp_path):
    clip(tmp_path / "set" / "x")
    clip(tmp_path / "set" / "sub" / "y")
    clip(tmp_path / "set" / ".cache" / "z")  # hidden and data folders are not searched
    clip(tmp_path / "set" / "x" / "gt" / "w")
    assert dataset_clips(tmp_path / "set") == [tmp_path / "set" / "sub" / "y", tmp_path / "set" / "x"]
    assert dataset_clips(tmp_path / "set" / "x") == [tmp_path / "set" / "x"]
    (tmp_path / "set" / "manifest.yaml").write_text("clips: [x]\n")
    x = [tmp_path / "set" / "x"]
    assert dataset_clips(tmp_path / "set") == dataset_clips(tmp_path / "set" / "manifest.yaml") == x
    assert dataset_clips(tmp_path / "nothing") == []


def test_check_names_the_file_of_a_readers_plain_value_error(tmp_path, capsys):
    """Two events cannot be given their own frames in a 1-frame clip: the reader says so with a ValueError
    that named no file, and stopped `rally3d check` (and train.py) with no clip checked after it."""
    clip(tmp_path / "a")
    (tmp_path / "a" / "clip.yaml").write_text(CLIP_YAML.replace("n_frames: 4", "n_frames: 1"))
    (tmp_path / "a" / "events.csv").write_text("frame,event\n0,ground\n0,net\n")
    clip(tmp_path / "b")
    (tmp_path / "b" / "ball.csv").write_text("frame,visibility,x,y\n0,1,0.5,0.5\n")
    assert main(["check", str(tmp_path)]) == 1
    out = capsys.readouterr().out
    assert f"FAIL {tmp_path / 'a' / 'events.csv'}: 2 events do not fit in 1 frames — fix: " in out
    assert "ok   ball.csv 1" in out and out.rstrip().endswith("2 of 2 clips have problems: a, b")  # no videos


def test_a_table_naming_an_absurd_frame_is_refused_without_a_length(tmp_path):
    """With no video and no n_frames, a table's last frame sizes the clip: 2e9 is refused, not allocated."""
    from inference.clipio import Clip, FormatError

    clip = tmp_path / "c"
    clip.mkdir()
    (clip / "clip.yaml").write_text("sport: padel\nfps: 30\nwidth: 1280\nheight: 720\nvideo: none.mp4\n")
    (clip / "events.csv").write_text("frame,event\n2000000000,ground\n")
    with pytest.raises(FormatError, match="beyond any video"):
        Clip(clip).frames_in_data()
