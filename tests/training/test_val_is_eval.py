"""Validation means what eval.py means (issue 41): with the same weights on the same clips, the
validation F1 that picks the best checkpoint is eval.py's F1 at τ = 4 px in original-frame pixels after
the tracker (and the max-score baseline's beside it), not a per-frame blob count at another τ."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from training_fixtures import compose_cfg, tiny_padel  # noqa: F401  (fixtures)

from training.detection.clip_scores import clip_reports, window_rows

SHIPPED = Path(__file__).resolve().parents[2] / "inference" / "weights" / "wasb_padel.pth.tar"


def test_validation_f1_is_eval_f1_with_the_same_weights(tiny_padel, tmp_path):
    from training.common import build
    from training.run import evaluate_detector

    over = ["+experiment=wasb_padel", f"data.root={tiny_padel}", f"init_weights={SHIPPED}", "trainer.accelerator=cpu",
            f"data.cache_dir={tmp_path / 'cache'}", "data.batch_size=4", "logger=[]"]
    cfg = compose_cfg(over, tmp_path / "run")
    dm, model, trainer = build(cfg)
    logged = trainer.validate(model, datamodule=dm, weights_only=True)[0]
    ev = evaluate_detector(compose_cfg(["+experiment=wasb_padel", f"data.root={tiny_padel}", f"ckpt_path={SHIPPED}",
                                        "split=val", "trainer.accelerator=cpu"], tmp_path / "eval", name="eval"))
    assert ev.n_clips == 1 and ev.f1s["f1_tau4_tracker"] > 0.5          # a real detection task, not 0 = 0
    assert logged["val/f1"] == pytest.approx(ev.f1s["f1_tau4_tracker"], abs=1e-6)
    assert logged["val/f1_tracker"] == pytest.approx(ev.f1s["f1_tau4_tracker"], abs=1e-6)
    assert logged["val/f1_max_score"] == pytest.approx(ev.f1s["f1_tau4_max-score"], abs=1e-6)
    assert "val/f1_blob" in logged                                       # the earlier measure, beside it


def _meta(n_windows: int, start0: int = 0, fps: float = 25.0):
    import torch

    return {"lb_scale": torch.ones(n_windows), "lb_pad": torch.zeros(n_windows, 2), "offset": torch.zeros(n_windows, 2),
            "visibility": torch.ones(n_windows, 3, dtype=torch.int64), "fps": torch.full((n_windows,), fps),
            "size": torch.tensor([[64.0, 48.0]] * n_windows), "clip": [0] * n_windows,
            "start": [start0 + 3 * k for k in range(n_windows)]}


def test_the_tracker_decides_between_two_blobs_as_in_inference():
    """A ball moving steadily plus a brighter static distractor that appears in some frames only: the
    per-frame best blob takes the distractor there, the tracker keeps the ball (what eval.py scores)."""
    n_win = 8
    probs = np.zeros((n_win, 3, 48, 64), np.float32)
    meta = _meta(n_win)
    gt = np.zeros((n_win, 3, 2))
    for w in range(n_win):
        for f in range(3):
            t = 3 * w + f
            x, y = 5 + 2 * t, 20 + 0.5 * t
            gt[w, f] = (x, y)
            probs[w, f, int(round(y)) - 1:int(round(y)) + 2, int(round(x)) - 1:int(round(x)) + 2] = 0.8
            if t % 4 == 3:
                probs[w, f, 40:45, 55:60] = 0.99                    # a distractor, larger and brighter
    import torch

    meta["xy_px"] = torch.as_tensor(gt)
    cands, frames = window_rows(probs, meta, frames_in=3)
    assert frames.shape == (24, 8) and cands.shape[1] == 6
    reports = clip_reports(cands, frames, tau_px=4.0)
    assert reports["tracker"].f1 > 0.95                                  # the ball in every frame
    best_blob_tp = sum(t % 4 != 3 for t in range(24))
    assert reports["max-score"].counts.tp <= best_blob_tp < 24           # the baseline falls for the distractor
