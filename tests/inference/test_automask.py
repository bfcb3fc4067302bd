"""``mask: auto``: a burnt-in scoreboard on a broadcast-like clip (the padel sample with sensor noise, a slow
camera drift and H.264) is found from its static pixels, written for the user to check, never covers the
court, and a clip too still to judge gets no mask and a note."""
from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml

from inference.camera import Camera
from inference.cli import main
from inference.clipio import Clip, FrameSource, write_video
from inference.court import load_court
from inference.courtfit.drift import court_line_samples
from inference.video.masks import AUTO_FILE, AUTO_PREVIEW, clip_mask
from inference.pipeline.prepare import request_auto_mask

SAMPLE = Path(__file__).resolve().parents[2] / "datasets" / "sample" / "padel_sample"
BOX = (40, 30, 360, 110)  # x0, y0, x1, y1 px of the scoreboard in the 1280×720 frame


def scoreboard(img: np.ndarray) -> np.ndarray:
    """A broadcast score panel: dark box, two lines of white text, a yellow serve dot (ball-like)."""
    x0, y0, x1, y1 = BOX
    img[y0:y1, x0:x1] = (25, 30, 70)
    for row, text in ((32, "LEBRON/GALAN  6 4 2"), (66, "COELLO/TAPIA  3 6 1")):
        cv2.putText(img, text, (x0 + 12, y0 + row), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2, cv2.LINE_AA)
    cv2.circle(img, (x1 - 20, y0 + 26), 6, (215, 232, 62), -1, cv2.LINE_AA)
    return img


@pytest.fixture(scope="module")
def broadcast(tmp_path_factory) -> Clip:
    """120 frames of the sample with noise (σ 2.5), a 6 px drift, the scoreboard keyed on top, H.264."""
    root = tmp_path_factory.mktemp("automask") / "broadcast"
    shutil.copytree(SAMPLE, root)
    rng = np.random.default_rng(0)
    frames = []
    with FrameSource.open(SAMPLE / "video.mp4") as src:
        for i, f in enumerate(src.iter(0, 120)):
            d = 6.0 * i / 119
            f = cv2.warpAffine(f, np.float32([[1, 0, d], [0, 1, -d / 2]]), (1280, 720), borderMode=cv2.BORDER_REPLICATE)
            frames.append(scoreboard(np.clip(f + rng.normal(0, 2.5, f.shape), 0, 255).astype(np.uint8)))
    write_video(root / "video.mp4", frames, 30.0, fourcc="h264", crf=20)
    (root / "clip.yaml").write_text((root / "clip.yaml").read_text().replace("n_frames: 240", "n_frames: 120")
                                    + "mask: auto\n")
    shutil.copy(root / "gt" / "camera.yaml", root / "camera.yaml")
    return Clip(root)


def test_auto_mask_covers_the_scoreboard_and_never_the_court(broadcast):
    rects = clip_mask(broadcast)
    assert len(rects) == 1, rects
    x0, y0, x1, y1 = rects[0].pixels(1280, 720)
    assert x0 <= BOX[0] and y0 <= BOX[1] and x1 >= BOX[2] and y1 >= BOX[3], (x0, y0, x1, y1)
    assert (x1 - x0) * (y1 - y0) < 1.6 * (BOX[2] - BOX[0]) * (BOX[3] - BOX[1])
    court = court_line_samples(Camera.load(broadcast.camera_path), load_court("padel"))
    assert not np.any((court[:, 0] >= x0) & (court[:, 0] < x1) & (court[:, 1] >= y0) & (court[:, 1] < y1))
    # written for the user: the boxes (editable) and a preview with them drawn
    saved = yaml.safe_load((broadcast.root / AUTO_FILE).read_text())
    assert len(saved["mask"]) == 1 and saved["n_frames"] == 120
    assert "edit the boxes here" in (broadcast.root / AUTO_FILE).read_text()
    preview = cv2.imread(str(broadcast.root / AUTO_PREVIEW))
    assert preview.shape == (720, 1280, 3) and preview[y0 + 1, (x0 + x1) // 2, 2] > 200  # the red frame


def test_a_corrected_mask_auto_file_is_used_as_it_stands(broadcast, tmp_path):
    clip = Clip(shutil.copytree(broadcast.root, tmp_path / "c"))
    clip_mask(clip)
    data = yaml.safe_load((clip.root / AUTO_FILE).read_text())
    data["mask"] = [[0.5, 0.5, 0.6, 0.6]]  # the user's correction
    (clip.root / AUTO_FILE).write_text(yaml.safe_dump(data))
    assert [r.pixels(1280, 720) for r in clip_mask(clip)] == [(640, 360, 768, 432)]
    data["n_frames"] = 999  # made for another video: searched again
    (clip.root / AUTO_FILE).write_text(yaml.safe_dump(data))
    assert clip_mask(clip)[0].pixels(1280, 720)[0] <= BOX[0]


def test_a_still_clip_gets_no_mask_and_a_note(tmp_path):
    clip = Clip(shutil.copytree(SAMPLE, tmp_path / "still"))  # noiseless synthetic frames: nothing moves
    (clip.root / "clip.yaml").write_text((clip.root / "clip.yaml").read_text() + "mask: auto\n")
    assert clip_mask(Clip(clip.root)) == []
    assert "note: the picture hardly changes" in (clip.root / AUTO_FILE).read_text()


def test_infer_mask_auto_writes_clip_yaml_with_a_backup(broadcast, tmp_path, capsys):
    clip = Clip(shutil.copytree(broadcast.root, tmp_path / "user"))
    text = (clip.root / "clip.yaml").read_text().replace("mask: auto\n", "")
    (clip.root / "clip.yaml").write_text(text)
    (clip.root / AUTO_FILE).unlink(missing_ok=True)
    assert main(["infer", str(clip.root), "--mask", "auto", "--only", "scenes", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "mask: auto written to" in out
    assert Clip(clip.root).info.extra["mask"] == "auto"
    backups = list((clip.root / ".rally3d" / "backup").glob("clip.yaml*"))
    assert len(backups) == 1 and "mask" not in backups[0].read_text()
    assert (clip.root / AUTO_FILE).is_file() and (clip.root / "scenes.json").is_file()  # the scenes stage masked
    (clip.root / "clip.yaml").write_text(text + "mask:\n  - [0.1, 0.1, 0.2, 0.2]\n")
    request_auto_mask(Clip(clip.root), log=print)
    assert "has its own mask rectangles" in capsys.readouterr().out
    assert Clip(clip.root).info.extra["mask"] == [[0.1, 0.1, 0.2, 0.2]]
