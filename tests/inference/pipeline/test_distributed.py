"""``rally3d infer`` on a Dask cluster (``--cluster``, ``--workers``): the same results as one process."""
from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import numpy as np
import pytest

from inference.cli import main
from inference.clipio import Clip

STAGES = "scenes,detect,smooth"


@pytest.fixture(scope="module")
def videos(tmp_path_factory) -> Path:
    """A folder of two short rendered padel videos and one file that is no video."""
    from synth.generate import SynthConfig, generate_clip

    root = tmp_path_factory.mktemp("dist")
    folder = root / "matches"
    folder.mkdir()
    for name, seed in (("a", 3), ("b", 4)):
        cfg = SynthConfig(sport="padel", camera="padel_installed", randomise_camera=False, fps=30.0, width=480,
                          height=270, codec="mp4v", max_frames=36)
        generate_clip(root / name, seed=seed, config=cfg)
        shutil.copy(root / name / "video.mp4", folder / f"{name}.mp4")
    return folder


def _ball(clip: Path) -> tuple[np.ndarray, np.ndarray]:
    b = Clip(clip).read_ball()
    return b.visibility, b.xy


def _same_results(one: Path, other: Path) -> None:
    va, xa = _ball(one)
    vb, xb = _ball(other)
    assert np.array_equal(va, vb)
    assert np.allclose(xa, xb, atol=1e-4, equal_nan=True), np.nanmax(np.abs(xa - xb))
    assert json.loads((one / "scenes.json").read_text()) == json.loads((other / "scenes.json").read_text())


def test_cluster_of_two_workers_gives_the_single_process_results(videos, tmp_path, capsys):
    from dask.distributed import LocalCluster

    single = tmp_path / "single"
    for v in ("a", "b"):
        assert main(["infer", str(videos / f"{v}.mp4"), "--court", "padel", "--only", STAGES, "--no-progress",
                     "--out", str(single / v)]) == 0
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster:
        out = tmp_path / "cluster"
        code = main(["infer", str(videos / "a.mp4"), str(videos / "b.mp4"), "--court", "padel", "--only", STAGES,
                     "--cluster", cluster.scheduler_address, "--out", str(out)])
    text = capsys.readouterr()
    assert code == 0, text.out + text.err
    assert "2 inputs on the Dask scheduler at" in text.err and "[2/2]" in text.err and "2/2 inputs complete" in text.out
    for v in ("a", "b"):
        _same_results(single / v, out / v)


def test_workers_run_a_folder_of_videos_and_a_bad_one_does_not_sink_the_rest(videos, tmp_path, capsys):
    folder = tmp_path / "folder"
    shutil.copytree(videos, folder)
    (folder / "c.mp4").write_bytes(b"not a video")
    out = tmp_path / "out"
    code = main(["infer", str(folder), "--court", "padel", "--only", "scenes", "--workers", "2", "--out", str(out)])
    text = capsys.readouterr()
    assert code == 1, text.out + text.err
    assert "a local Dask cluster of 2 worker processes" in text.err
    assert "2/3 inputs complete" in text.out
    assert f"== {folder / 'c.mp4'} → -: INCOMPLETE" in text.out and "c.mp4" in text.out
    for v in ("a", "b"):
        assert (out / v / "scenes.json").is_file()
    assert main(["infer", str(folder), "--court", "padel", "--workers", "0"]) != 0
    assert "--workers '0': a number of processes" in capsys.readouterr().err
