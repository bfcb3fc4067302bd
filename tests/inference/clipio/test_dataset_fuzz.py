"""Fuzz tests (hypothesis) of train.py's dataset reading: a dataset folder whose clip files are random or
shaped like the real ones (clip.yaml, ball.csv, events.csv, the video, sometimes a manifest.yaml) →
the preflight check (:func:`training.preflight.check_clips`' :func:`~inference.cli_commands.check_paths`)
returns problems, never raises; and when it finds none, the data modules' readers read every clip without
an exception. Same profiles as test_clipio_fuzz.py (derandomized in the suite); a longer search::

    RALLY3D_FUZZ=2000 .venv/bin/python -m pytest tests/inference/clipio/test_dataset_fuzz.py
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import event, example, given  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from test_clipio_fuzz import FUZZ, csv_text, file_bytes, yaml_doc  # noqa: E402

from inference.cli_commands import check_paths  # noqa: E402
from inference.clipio import EVENT_LABELS, write_video  # noqa: E402
from training.preflight import detector_files, event_files  # noqa: E402

CLIP_YAML = {"sport": "padel", "fps": 30, "width": 64, "height": 48, "video": "video.mp4", "n_frames": 12}
GOOD_BALL = "frame,visibility,x,y\n0,1,0.5,0.5\n3,2,0.25,0.75\n11,0,,\n"
GOOD_EVENTS = "frame,event\n2,ground\n7,player_near\n"
NAMES = ["c0", "c1", "c2"]


@pytest.fixture(scope="module")
def videos(tmp_path_factory) -> dict[str, bytes]:
    """A valid 12-frame 64×48 video, the same cut in half, empty, and random bytes."""
    path = tmp_path_factory.mktemp("video") / "video.mp4"
    rng = np.random.default_rng(0)
    write_video(path, (rng.integers(0, 255, (48, 64, 3), np.uint8) for _ in range(12)), 30.0)
    data = path.read_bytes()
    return {"valid": data, "cut": data[: len(data) // 2], "empty": b"", "junk": bytes(rng.integers(0, 255, 300,
                                                                                                 np.uint8))}


coord = st.one_of(st.floats(-0.2, 1.2), st.just(""))
frame = st.one_of(st.just(0), st.integers(0, 3), st.integers(-1, 40))  # crowded at the start, past the end
near_ball = st.builds(lambda rows: "frame,visibility,x,y\n" + "".join(f"{f},{v},{x},{y}\n" for f, v, x, y in rows),
                      st.lists(st.tuples(frame, st.integers(0, 4), coord, coord), max_size=12)).map(str.encode)
near_events = st.builds(lambda rows: "frame,event\n" + "".join(f"{f},{e}\n" for f, e in rows),
                        st.lists(st.tuples(frame, st.sampled_from([*EVENT_LABELS, "hit", "bounce", ""])),
                                 max_size=8)).map(str.encode)
near_clip_yaml = st.fixed_dictionaries({
    "sport": st.sampled_from(["padel", "padel", "tennis", "squash"]), "fps": st.sampled_from([30, 25.0, 60, 0]),
    "width": st.sampled_from([64, 64, 32]), "height": st.sampled_from([48, 48, 36]),
    "video": st.sampled_from(["video.mp4", "video.mp4", "other.mp4", "frames/"]),
    "n_frames": st.sampled_from([None, None, 1, 2, 5, 12, 30]),
}).map(lambda d: yaml.safe_dump({k: v for k, v in d.items() if v is not None}).encode())


GOOD = {"clip.yaml": yaml.safe_dump(CLIP_YAML).encode(), "ball.csv": GOOD_BALL.encode(),
        "events.csv": GOOD_EVENTS.encode(), "video.mp4": "valid"}
PLAUSIBLE = {"clip.yaml": near_clip_yaml, "ball.csv": st.one_of(st.none(), near_ball),  # right layout, values at
             "events.csv": st.one_of(st.none(), near_events), "video.mp4": st.sampled_from(["valid", None])}  # edges
FUZZED = {"clip.yaml": st.one_of(st.none(), file_bytes(yaml_doc([*CLIP_YAML, "split", "match"], CLIP_YAML))),
          "ball.csv": st.one_of(st.none(), file_bytes(csv_text(["frame", "visibility", "x", "y"]))),
          "events.csv": st.one_of(st.none(), file_bytes(csv_text(["frame", "event"]))),
          "video.mp4": st.sampled_from([None, "cut", "empty", "junk"])}


def clip_of(kinds: dict[str, st.SearchStrategy]) -> st.SearchStrategy[dict]:
    """A clip's files, each the valid one or drawn from ``kinds`` (None: the file is absent)."""
    return st.fixed_dictionaries({name: st.one_of(st.just(GOOD[name]), kinds[name]) for name in GOOD})


one_fuzzed = st.sampled_from(list(GOOD)).flatmap(lambda name: FUZZED[name].map(lambda v: {**GOOD, name: v}))
clip_files = st.one_of(clip_of(PLAUSIBLE), clip_of(PLAUSIBLE), one_fuzzed, clip_of(FUZZED))
manifest = st.one_of(st.none(), st.none(), file_bytes(yaml_doc(["name", "sport", "clips", "source"], {
    "name": "d", "clips": [{"path": n, "split": s} for n, s in zip(NAMES, ["train", "val", "test"])]})))
dataset = st.tuples(st.lists(clip_files, min_size=1, max_size=3), manifest)


def write_dataset(root: Path, clips: list[dict], manifest_bytes: bytes | None, videos: dict[str, bytes]) -> None:
    """The clip folders (a file is left out where its value is None) and the manifest, in a fresh ``root``."""
    shutil.rmtree(root, ignore_errors=True)
    for name, files in zip(NAMES, clips):
        (root / name).mkdir(parents=True)
        for file, data in files.items():
            if data is not None:
                (root / name / file).write_bytes(videos[data] if file == "video.mp4" else data)
    if manifest_bytes is not None:
        (root / "manifest.yaml").write_bytes(manifest_bytes)


def read_detector_clips(root: Path, cache: Path) -> None:
    """What BallDataModule reads of every labelled clip (frame cache included)."""
    from inference.clipio import Clip
    from training.datasets import resolve_sources, skip_unlabelled
    from training.detection.data import load_clip

    for src in resolve_sources([str(root)]):
        for clip in skip_unlabelled([Clip(p) for p in src.paths(None)], "ball.csv", str(root)):
            load_clip(clip, (16, 16), cache)


def read_event_clips(root: Path) -> None:
    """What EventDataModule reads of every clip with ball.csv and events.csv, and their class labels."""
    from inference.events.classes import ClassSet
    from inference.events.features import FeatureConfig
    from training.events.data.datamodule import clips_with_source, label_clips

    sims = [c for c, _ in clips_with_source(str(root), "all")]
    label_clips(sims, ClassSet.load("padel6"), FeatureConfig())


@pytest.mark.parametrize("task", ["detector", "events"])
def test_dataset_check_reports_problems_or_the_run_reads_every_clip(task, tmp_path, videos):
    from training.preflight import event_labels

    files = detector_files if task == "detector" else event_files
    labels = None if task == "detector" else event_labels({"task": "events", "data": {"class_set": "padel6"}})
    root = tmp_path / "data"

    @FUZZ
    @given(data=dataset)
    @example(data=([{**GOOD, "clip.yaml": GOOD["clip.yaml"].replace(b"n_frames: 12", b"n_frames: 1"),
                     "events.csv": b"frame,event\n0,ground\n0,net\n"}], None))  # 2 events cannot fit in 1 frame
    def run(data) -> None:
        clips, manifest_bytes = data
        write_dataset(root, clips, manifest_bytes, videos)
        report = check_paths([root], files=files, labels=labels)  # never raises
        if report.problems or not any(files(c.root) for c in report.clips):
            event("problems: train.py stops with the list")
            return
        event("no problem: every clip read")
        if task == "detector":
            read_detector_clips(root, tmp_path / "cache")
        else:
            read_event_clips(root)

    run()
