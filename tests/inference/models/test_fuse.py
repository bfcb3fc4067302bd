"""Batch-norm folding: same outputs as the eval-mode model, for every detector architecture."""
from __future__ import annotations

import pytest
import torch

from inference.detection.detect import BallDetectorRunner
from inference.models.fuse import fold_batchnorm
from inference.models.registry import MODEL_NAMES, build_model


@pytest.mark.parametrize("name", MODEL_NAMES)
def test_folded_model_gives_the_same_logits(name):
    torch.manual_seed(0)
    model = build_model(name)
    # non-trivial BN statistics, as after training
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm2d):
            m.running_mean.uniform_(-0.5, 0.5)
            m.running_var.uniform_(0.5, 2.0)
            m.weight.data.uniform_(0.5, 1.5)
            m.bias.data.uniform_(-0.2, 0.2)
    model.eval()
    folded, n = fold_batchnorm(model)
    n_bn = sum(isinstance(m, torch.nn.BatchNorm2d) for m in model.modules())
    assert sum(isinstance(m, torch.nn.BatchNorm2d) for m in folded.modules()) == n_bn - n
    if name != "tracknetv2":  # TrackNetV2 is conv → ReLU → BN: nothing to fold
        assert n > 0
    if name in ("wasb", "monotrack"):  # every BN follows its convolution: all folded (named pairs too)
        assert n == n_bn
    x = torch.randn(1, 9, 96, 160)
    with torch.inference_mode():
        ref, out = model(x), folded(x)
    ref = ref[0] if isinstance(ref, (dict, list, tuple)) else ref
    out = out[0] if isinstance(out, (dict, list, tuple)) else out
    torch.testing.assert_close(out, ref, rtol=1e-4, atol=1e-4)


def test_runner_folds_a_copy_and_leaves_the_trained_model_alone():
    model = build_model("wasb")
    runner = BallDetectorRunner(model)
    assert runner.model is not model
    assert any(isinstance(m, torch.nn.BatchNorm2d) for m in model.modules())
    assert model.training  # untouched: still trainable
