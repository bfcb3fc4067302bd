"""Names that cannot be confused (issue 43): the stretch of a broadcast between two editor's cuts is a *scene*
(``inference/video/scenes.py``, ``scenes.json``); a *shot* is a player's, from a racket hit to the next
(``labeler/review/shots.py``, the review's ``shots.csv``). The camera sense's former file name, ``shots.json``,
is read only by the compatibility reader of old clip folders (:func:`inference.video.scenes.scenes_file`)."""
from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
COMPAT_READER = ROOT / "inference" / "video" / "scenes.py"  # the one module that may name the old file
OLD_FILE = "shots.json"


def mentions(root: Path, text: str, base: Path = ROOT) -> list[str]:
    """The Python files under ``root`` whose text contains ``text``, as paths relative to ``base``."""
    return sorted(p.relative_to(base).as_posix() for p in root.rglob("*.py") if text in p.read_text(encoding="utf-8"))


def test_only_the_compat_reader_names_the_old_scenes_file():
    found = mentions(ROOT / "inference", OLD_FILE)
    assert str(COMPAT_READER.relative_to(ROOT)) in found  # the check looks where the file is named
    others = [p for p in found if ROOT / p != COMPAT_READER]
    assert not others, (f"{others} name {OLD_FILE}: the camera's stretches between cuts are scenes (scenes.json, "
                        "inference.video.scenes.scenes_file reads an old folder's file); a shot is a player's")


def test_the_check_finds_a_mention(tmp_path):
    """The scan above is real: a module naming the old file is found, one naming the new file is not."""
    (tmp_path / "pkg" / "sub").mkdir(parents=True)
    (tmp_path / "pkg" / "sub" / "stage.py").write_text(f'PATH = root / "{OLD_FILE}"\n')
    (tmp_path / "pkg" / "other.py").write_text('PATH = root / "scenes.json"\n')
    assert mentions(tmp_path / "pkg", OLD_FILE, base=tmp_path) == ["pkg/sub/stage.py"]


def test_no_camera_shots_module():
    """The camera module is inference.video.scenes; no module or import by the old names comes back."""
    assert not (ROOT / "inference" / "shots.py").exists()
    assert not (ROOT / "inference" / "pipeline" / "per_shot.py").exists()
    for package in ("inference", "labeler", "training", "bench", "tests"):
        for text in ("inference.shots", "pipeline.per_shot", "from .per_shot"):
            assert not [p for p in mentions(ROOT / package, text) if p != "tests/test_names.py"], text
