"""Every clip of a dataset is checked before training (and by ``rally3d check DATASET``): all the problems at
once, each naming its file, line and fix, then a summary and exit code 1, never a traceback at the first
broken clip."""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from training_fixtures import ROOT, compose_cfg, labeler_clips  # noqa: F401  (fixtures)

from inference.cli import main
from inference.clipio import Manifest, ManifestEntry
from training.datasets import resolve_source
from training.preflight import check_data, event_labels


def broken_copy(src: Path, dst: Path) -> Path:
    """The labeler clips with three broken: a ball.csv row, a clip.yaml value, an empty video."""
    shutil.copytree(src, dst)
    ball = dst / "a_25fps" / "ball.csv"
    lines = ball.read_text().splitlines()
    lines[2] = "1,1,1.7,0.5"  # line 3: x outside [0, 1]
    ball.write_text("\n".join(lines) + "\n")
    yaml_path = dst / "b_partial" / "clip.yaml"
    yaml_path.write_text(yaml_path.read_text().replace("fps: 50.0", "fps: -50"))
    (dst / "d_30fps" / "video.mp4").write_bytes(b"")
    return dst


def problems_of(excinfo: pytest.ExceptionInfo) -> str:
    return str(excinfo.value.code)


def test_training_lists_every_broken_clip_before_anything_is_built(labeler_clips, tmp_path):
    root = broken_copy(labeler_clips, tmp_path / "my_clips")
    cfg = compose_cfg(["+experiment=wasb_padel", f"data.root={root}"], tmp_path / "run")
    with pytest.raises(SystemExit) as e:
        check_data(cfg)
    text = problems_of(e)
    assert "3 of 5 clips have problems: a_25fps, b_partial, d_30fps" in text
    assert f"{root}/a_25fps/ball.csv, line 3:" in text
    assert f"{root}/b_partial/clip.yaml, line " in text and "fps must be a number > 0" in text
    assert f"{root}/d_30fps/video.mp4: the video file is empty" in text
    assert text.count(" — fix: ") == 3  # each problem says how to fix it
    assert "rally3d check" in text and "Traceback" not in text
    assert not (tmp_path / "run" / "checkpoints").exists()


def test_train_py_exits_1_with_the_list_and_no_traceback(labeler_clips, tmp_path):
    root = broken_copy(labeler_clips, tmp_path / "my_clips")
    out = subprocess.run([sys.executable, "train.py", "+experiment=wasb_padel", f"data.root={root}",
                          f"paths.log_dir={tmp_path}/runs"], cwd=ROOT, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"})
    assert out.returncode == 1, out.stderr[-2000:]
    assert "3 of 5 clips have problems" in out.stderr and "Traceback" not in out.stderr, out.stderr[-2000:]
    assert "ball.csv, line 3" in out.stderr and "clip.yaml" in out.stderr and "video.mp4" in out.stderr


def test_a_clean_folder_passes_and_unlabelled_clips_are_no_problem(labeler_clips, tmp_path):
    cfg = compose_cfg(["+experiment=wasb_padel", f"data.root={labeler_clips}"], tmp_path / "run")
    check_data(cfg)  # e_unlabelled has no ball.csv: skipped by the run, not a problem
    events = compose_cfg(["+experiment=hitnet_padel_finetune", f"data.root={labeler_clips}"], tmp_path / "run")
    check_data(events)  # c_60fps_4k has no events.csv: skipped too


def test_hit_event_runs_check_what_they_read(labeler_clips, tmp_path):
    """Events: ball.csv and events.csv (frames within clip.yaml's n_frames, labels the class set maps); the
    video only counts frames, so an empty video is no problem when clip.yaml gives n_frames."""
    root = tmp_path / "my_clips"
    shutil.copytree(labeler_clips, root)
    (root / "a_25fps" / "events.csv").write_text("frame,event\n3,ground\n9999,net\n")
    (root / "d_30fps" / "video.mp4").write_bytes(b"")
    cfg = compose_cfg(["+experiment=hitnet_padel_finetune", f"data.root={root}"], tmp_path / "run")
    with pytest.raises(SystemExit) as e:
        check_data(cfg)
    text = problems_of(e)
    assert "1 of 5 clips have problems: a_25fps" in text and f"{root}/a_25fps/events.csv, line 3" in text
    tennis = ["+experiment=hitnet_tennis_finetune", f"data.root={root}"]
    assert event_labels(compose_cfg(tennis, tmp_path / "run")) is None  # on_unmapped: warn, any label
    labels = event_labels(compose_cfg([*tennis, "data.on_unmapped=error"], tmp_path / "run"))
    assert "wall_left" not in labels and "ground" in labels
    assert event_labels(compose_cfg(["+experiment=wasb_padel"], tmp_path / "run")) is None


def test_nothing_labelled_is_said_before_training(labeler_clips, tmp_path):
    root = tmp_path / "my_clips"
    shutil.copytree(labeler_clips / "e_unlabelled", root / "e_unlabelled")
    cfg = compose_cfg(["+experiment=wasb_padel", f"data.root={root}"], tmp_path / "run")
    with pytest.raises(SystemExit, match="none of the 1 clips has ball.csv: nothing to train on"):
        check_data(cfg)


def test_rally3d_check_takes_a_dataset_and_reports_every_clip(labeler_clips, tmp_path, capsys):
    root = broken_copy(labeler_clips, tmp_path / "my_clips")
    assert main(["check", str(root)]) == 1
    out = capsys.readouterr().out
    assert out.count("FAIL") == 3 and "ball.csv, line 3" in out and "video file is empty" in out
    assert "ok   ball.csv" in out  # the clips after the first broken one are checked too
    assert out.rstrip().endswith("3 of 5 clips have problems: a_25fps, b_partial, d_30fps")
    # a manifest (the folder or the file): an entry without its clip folder is one more problem, the rest checked
    Manifest(root, [ManifestEntry("a_25fps", "train"), ManifestEntry("gone", "val"),
                    ManifestEntry("c_60fps_4k", "test")]).save()
    for target in (root, root / "manifest.yaml"):
        assert main(["check", str(target)]) == 1
        out = capsys.readouterr().out
        assert "FAIL" in out and "clip folder gone has no clip.yaml" in out and "ok   ball.csv" in out
        assert "1 of 2 clips have problems: a_25fps; 1 problem(s) in the dataset itself (its manifest)" in out
    assert main(["check", str(labeler_clips)]) == 0
    assert capsys.readouterr().out.rstrip().endswith("5 clips, all fine")


def test_a_saved_manifest_file_is_a_data_root(labeler_clips, tmp_path):
    saved = Manifest(tmp_path, [ManifestEntry(str(labeler_clips / "d_30fps"), "train")]).save(tmp_path / "m.yaml")
    source = resolve_source(saved)
    assert source.root == tmp_path and source.paths("train") == [labeler_clips / "d_30fps"]
    check_data(compose_cfg(["+experiment=wasb_padel", f"data.root={saved}"], tmp_path / "run"))


def test_event_clips_without_video_count_frames_from_their_events(tmp_path):
    """Found by tests/inference/clipio/test_dataset_fuzz.py: no n_frames, no video and a header-only ball.csv
    gave the clip 0 frames although events.csv names frames 2 and 7 (an IndexError deep in the features); a
    clip where nothing names a frame is skipped like an unlabelled one."""
    from training.events.data.datamodule import clips_with_source

    for name, events in (("a", "frame,event\n2,ground\n7,player_near\n"), ("b", "frame,event\n")):
        (tmp_path / name).mkdir()
        (tmp_path / name / "clip.yaml").write_text("sport: padel\nfps: 30\nwidth: 64\nheight: 48\nvideo: v.mp4\n")
        (tmp_path / name / "ball.csv").write_text("frame,visibility,x,y\n")
        (tmp_path / name / "events.csv").write_text(events)
    sims = [c for c, _ in clips_with_source(str(tmp_path), "all")]
    assert [(Path(c.name).name, c.n_frames) for c in sims] == [("a", 8)]
