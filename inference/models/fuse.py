"""Inference-only graph simplification: batch-norm folded into the preceding convolution."""
from __future__ import annotations

import copy

from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval


def fold_batchnorm(model: nn.Module) -> tuple[nn.Module, int]:
    """A copy of ``model`` (in eval mode) with every ``Conv2d`` directly followed by a ``BatchNorm2d`` inside an
    ``nn.Sequential`` folded into that convolution; returns the copy and the number of folded pairs.

    The outputs are those of ``model.eval()`` up to float rounding; the copy must not be trained (its BN
    statistics are baked in). Conv→ReLU→BN orders and convs outside a Sequential are left as they are.
    """
    model = copy.deepcopy(model).eval()
    folded = 0
    for seq in model.modules():
        if not isinstance(seq, nn.Sequential):
            continue
        names = list(seq._modules)
        for a, b in zip(names, names[1:]):
            conv, bn = seq._modules[a], seq._modules[b]
            if isinstance(conv, nn.Conv2d) and isinstance(bn, nn.BatchNorm2d):
                seq._modules[a] = fuse_conv_bn_eval(conv, bn)
                seq._modules[b] = nn.Identity()
                folded += 1
    return model, folded
