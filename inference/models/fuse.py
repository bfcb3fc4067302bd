"""Inference-only graph simplification: batch-norm folded into the preceding convolution."""
from __future__ import annotations

import copy

from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval

CONV_BN_PAIRS = "conv_bn_pairs"
"""Name of an optional class attribute: ``(conv_name, bn_name)`` child pairs whose ``forward`` applies the BN
directly to that convolution's output (and uses neither anywhere else), e.g. ``(("conv1", "bn1"),)``."""


def fold_batchnorm(model: nn.Module) -> tuple[nn.Module, int]:
    """A copy of ``model`` (in eval mode) with batch norms folded into their convolutions; returns the copy and
    the number of folded pairs.

    Two places are folded: a ``Conv2d`` directly followed by a ``BatchNorm2d`` inside an ``nn.Sequential``,
    and the named child pairs a module class declares in its ``conv_bn_pairs`` attribute (blocks that call
    ``self.bn1(self.conv1(x))`` in their ``forward``); the folded BN becomes an ``nn.Identity``.
    The outputs are those of ``model.eval()`` up to float rounding; the copy must not be trained (its BN
    statistics are baked in). Conv→ReLU→BN orders are left as they are.
    """
    model = copy.deepcopy(model).eval()
    folded = 0
    for module in model.modules():
        if isinstance(module, nn.Sequential):
            names = list(module._modules)
            pairs = list(zip(names, names[1:]))
        else:
            pairs = list(getattr(type(module), CONV_BN_PAIRS, ()))
        for a, b in pairs:
            conv, bn = module._modules.get(a), module._modules.get(b)
            if isinstance(conv, nn.Conv2d) and isinstance(bn, nn.BatchNorm2d):
                module._modules[a] = fuse_conv_bn_eval(conv, bn)
                module._modules[b] = nn.Identity()
                folded += 1
    return model, folded
