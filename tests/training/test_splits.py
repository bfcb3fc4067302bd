"""Which clips a run trains, validates and is evaluated on when the clips state their split in clip.yaml
(issue 41): eval.py scores the test split, not the training clips; a dataset without a val split gets one
carved from its training clips (by clip or match, seeded), said in one line."""
from __future__ import annotations

import logging
import shutil

from training_fixtures import compose_cfg, labeler_clips  # noqa: F401  (fixtures)

from inference.clipio import Clip, Manifest, ManifestEntry
from training.datasets import carve_val, resolve_sources
from training.run import eval_clips

STATED = {"a_25fps": "train", "b_partial": "train", "c_60fps_4k": "train", "d_30fps": "train",
          "e_unlabelled": "test"}


def _stated_copy(src, dst, splits: dict[str, str | None]):
    shutil.copytree(src, dst)
    for name, split in splits.items():
        clip = Clip(dst / name)
        info = clip.info
        info.split = split
        clip.write_info(info)
    return dst


def test_eval_scores_the_test_split_when_clips_state_their_splits(labeler_clips, tmp_path):
    splits = {**STATED, "a_25fps": "test", "e_unlabelled": "train"}   # a and the unlabelled e swap roles
    root = _stated_copy(labeler_clips, tmp_path / "stated", splits)
    cfg = compose_cfg(["+experiment=wasb_padel", f"data.root={root}"], tmp_path / "eval", name="eval")
    clips, _, split = eval_clips(cfg)
    assert split == "test"
    assert [c.root.name for c in clips] == ["a_25fps"]       # not the training clips train.py used
    # a plain folder whose clips state nothing is still scored whole
    plain = compose_cfg(["+experiment=wasb_padel", f"data.root={labeler_clips}"], tmp_path / "eval2", name="eval")
    clips, _, split = eval_clips(plain)
    assert split == "all" and len(clips) == 4                 # e has no ball.csv


def test_a_dataset_without_val_split_gets_one_carved_from_training_clips(labeler_clips, tmp_path, caplog):
    root = _stated_copy(labeler_clips, tmp_path / "noval", STATED)
    with caplog.at_level(logging.INFO, logger="training.datasets"):
        src = resolve_sources(str(root), seed=3)[0]
    val = src.paths("val")
    assert len(val) >= 1 and src.carved == sorted(p.name for p in val)
    assert {p.name for p in src.paths("test")} == {"e_unlabelled"}    # stated splits other than train stay
    train = {p.name for p in src.paths("train")}
    assert train and not train & {p.name for p in val}
    # by match: c and d share clip.yaml's match, so they stay together
    assert ({"c_60fps_4k", "d_30fps"} <= train) or ({"c_60fps_4k", "d_30fps"} <= {p.name for p in val})
    lines = [r.getMessage() for r in caplog.records if "no val split" in r.getMessage()]
    assert len(lines) == 1 and "seed 3" in lines[0]
    assert resolve_sources(str(root), seed=3)[0].carved == src.carved     # seeded
    for name in STATED:                                                    # the user's files are untouched
        assert Clip(root / name).info.split == STATED[name]


def test_nothing_is_carved_when_a_val_split_exists_or_one_clip_trains(tmp_path):
    m = Manifest(tmp_path, [ManifestEntry("a", "train"), ManifestEntry("b", "val")])
    assert carve_val(m) == [] and [c.split for c in m.clips] == ["train", "val"]
    one = Manifest(tmp_path, [ManifestEntry("a", "train"), ManifestEntry("t", "test")])
    assert carve_val(one) == [] and [c.split for c in one.clips] == ["train", "test"]
    many = Manifest(tmp_path, [ManifestEntry(f"c{i}", "train") for i in range(20)])
    moved = carve_val(many, seed=1)
    assert len(moved) == 2 and sum(c.split == "val" for c in many.clips) == 2   # 10 % of the groups
