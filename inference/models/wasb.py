"""WASB ball detector: the HRNet of WASB-SBDT (``src/models/hrnet.py`` with ``configs/model/wasb.yaml``),
weight-compatible with its public ``wasb_*_best.pth.tar`` checkpoints.

Layout (channels @ resolution for a 288×512 input)::

    conv1/bn1, conv2/bn2      stem, 3×3 stride 1 twice: 9 -> 64 -> 64             @ 288×512
    layer1.0                  Bottleneck 64 -> 32 -> 128 (1×1 downsample shortcut)
    transition1, stage2.0     branches [16, 32]            @ 1, 1/2
    transition2, stage3.0     branches [16, 32, 64]        @ 1, 1/2, 1/4
    transition3, stage4.0     branches [16, 32, 64, 128]   @ 1, 1/2, 1/4, 1/8
    final_layers.0            1×1 16 -> frames_out with bias, on the full-resolution branch (logits)

Each stage is one :class:`HighResolutionModule`: two BasicBlocks per branch, then every branch receives
the sum of all branches (resampled by the fuse rule) followed by a ReLU. All convolutions are bias-free
except the head. ``stage4.0`` carries fuse paths into all four branches, as the checkpoints do, but only
the full-resolution output feeds the head, so the others are never computed here.
"""
from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from .layers import check_input, conv_bn_relu

STEM_CHANNELS = 64
STAGE1_PLANES = 32  # Bottleneck width; its output is 4× this
BRANCH_CHANNELS = (16, 32, 64, 128)  # stage k (2..4) uses the first k branches
BLOCKS_PER_BRANCH = 2


class BasicBlock(nn.Module):
    """Two 3×3 conv-BN with an identity shortcut: ``(B, C, H, W) -> (B, C, H, W)``."""

    conv_bn_pairs = (("conv1", "bn1"), ("conv2", "bn2"))  # folded for inference (models/fuse.py)

    def __init__(self, channels: int):
        super().__init__()
        self.conv1 = nn.Conv2d(channels, channels, 3, padding=1, bias=False)
        self.bn1 = nn.BatchNorm2d(channels, momentum=0.1)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(channels, momentum=0.1)
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return self.relu(out + x)


class Bottleneck(nn.Module):
    """1×1 -> 3×3 -> 1×1 (×4 expansion) with a 1×1 conv-BN ``downsample`` shortcut:
    ``(B, C_in, H, W) -> (B, 4·planes, H, W)``."""

    expansion = 4
    conv_bn_pairs = (("conv1", "bn1"), ("conv2", "bn2"), ("conv3", "bn3"))

    def __init__(self, in_channels: int, planes: int):
        super().__init__()
        out_channels = planes * self.expansion
        self.conv1 = nn.Conv2d(in_channels, planes, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(planes, momentum=0.1)
        self.conv2 = nn.Conv2d(planes, planes, 3, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(planes, momentum=0.1)
        self.conv3 = nn.Conv2d(planes, out_channels, 1, bias=False)
        self.bn3 = nn.BatchNorm2d(out_channels, momentum=0.1)
        self.relu = nn.ReLU(inplace=True)
        self.downsample = nn.Sequential(*conv_bn_relu(in_channels, out_channels, kernel_size=1, relu=False))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.relu(self.bn1(self.conv1(x)))
        out = self.relu(self.bn2(self.conv2(out)))
        out = self.bn3(self.conv3(out))
        return self.relu(out + self.downsample(x))


def fuse_path(channels: Sequence[int], src: int, dst: int) -> nn.Module:
    """The path that carries branch ``src`` to branch ``dst`` (branch k is at 1/2^k resolution).

    - ``src == dst``: identity.
    - ``src > dst`` (lower to higher resolution): 1×1 conv, BN, nearest upsampling by ``2^(src-dst)``.
    - ``src < dst``: ``dst - src`` 3×3 stride-2 convs; the intermediate ones keep ``channels[src]`` and
      have BN+ReLU, the last maps to ``channels[dst]`` with BN only.

    ``(B, channels[src], H_src, W_src) -> (B, channels[dst], H_dst, W_dst)``.
    """
    if src == dst:
        return nn.Identity()
    if src > dst:
        return nn.Sequential(
            *conv_bn_relu(channels[src], channels[dst], kernel_size=1, relu=False),
            nn.Upsample(scale_factor=2 ** (src - dst), mode="nearest"),
        )
    steps = []
    for k in range(dst - src):
        last = k == dst - src - 1
        out = channels[dst] if last else channels[src]
        steps.append(nn.Sequential(*conv_bn_relu(channels[src], out, stride=2, relu=not last)))
    return nn.Sequential(*steps)


class HighResolutionModule(nn.Module):
    """Parallel branches plus a full fusion: a list of ``(B, channels[k], H/2^k, W/2^k)`` in, the same out.

    Keys: ``branches.{k}.{block}.*`` and ``fuse_layers.{dst}.{src}.*`` (identities hold no tensors).
    """

    def __init__(self, channels: Sequence[int], num_blocks: int = BLOCKS_PER_BRANCH):
        super().__init__()
        n = len(channels)
        self.branches = nn.ModuleList(
            nn.Sequential(*(BasicBlock(c) for _ in range(num_blocks))) for c in channels
        )
        self.fuse_layers = nn.ModuleList(
            nn.ModuleList(fuse_path(channels, src, dst) for src in range(n)) for dst in range(n)
        )
        self.relu = nn.ReLU(inplace=True)

    def forward(self, xs: list[torch.Tensor], num_outputs: int | None = None) -> list[torch.Tensor]:
        """Run the branches, then fuse into the first ``num_outputs`` branches (default: all)."""
        xs = [branch(x) for branch, x in zip(self.branches, xs)]
        outputs = len(xs) if num_outputs is None else num_outputs
        fused = []
        for paths in self.fuse_layers[:outputs]:
            y = paths[0](xs[0])
            for path, x in zip(paths[1:], xs[1:]):
                y = y + path(x)
            fused.append(self.relu(y))
        return fused


def transition(prev_channels: Sequence[int], channels: Sequence[int]) -> nn.ModuleList:
    """Adapt the previous stage's branches to the next stage, which adds one lower-resolution branch.

    An existing branch is kept (identity) or re-projected by a 3×3 conv-BN-ReLU when its width changes;
    the new branch is a 3×3 stride-2 conv-BN-ReLU of the previous stage's lowest-resolution output, under
    an extra ``Sequential`` level (keys ``{k}.0.0.*``) as in the checkpoints.
    """
    if len(channels) != len(prev_channels) + 1:
        raise ValueError("each HRNet stage adds exactly one branch")
    layers: list[nn.Module] = [
        nn.Identity() if prev == cur else nn.Sequential(*conv_bn_relu(prev, cur))
        for prev, cur in zip(prev_channels, channels)
    ]
    layers.append(nn.Sequential(nn.Sequential(*conv_bn_relu(prev_channels[-1], channels[-1], stride=2))))
    return nn.ModuleList(layers)


class WASB(nn.Module):
    """WASB-SBDT's HRNet ball detector.

    Args:
        frames_in: consecutive RGB frames stacked on channels (input has ``3 * frames_in`` channels).
        frames_out: heatmaps predicted, one per frame.

    Input ``(B, 3·frames_in, H, W)`` float (WASB normalises with ImageNet mean/std), H and W multiples of
    8 (default 288×512). Output ``(B, frames_out, H, W)`` logits: apply a sigmoid for heatmaps.
    1,481,427 parameters for the default 3 in / 3 out.
    """

    conv_bn_pairs = (("conv1", "bn1"), ("conv2", "bn2"))  # the stem

    def __init__(self, frames_in: int = 3, frames_out: int = 3):
        super().__init__()
        self.frames_in = frames_in
        self.frames_out = frames_out
        self.conv1 = nn.Conv2d(3 * frames_in, STEM_CHANNELS, 3, padding=1, bias=False)
        self.bn1 = nn.BatchNorm2d(STEM_CHANNELS, momentum=0.1)
        self.conv2 = nn.Conv2d(STEM_CHANNELS, STEM_CHANNELS, 3, padding=1, bias=False)
        self.bn2 = nn.BatchNorm2d(STEM_CHANNELS, momentum=0.1)
        self.relu = nn.ReLU(inplace=True)
        self.layer1 = nn.Sequential(Bottleneck(STEM_CHANNELS, STAGE1_PLANES))

        stage_channels = [BRANCH_CHANNELS[:k] for k in (2, 3, 4)]
        prev = (STAGE1_PLANES * Bottleneck.expansion,)
        for i, channels in enumerate(stage_channels, start=1):
            setattr(self, f"transition{i}", transition(prev, channels))
            setattr(self, f"stage{i + 1}", nn.Sequential(HighResolutionModule(channels)))
            prev = channels
        self.final_layers = nn.ModuleList([nn.Conv2d(BRANCH_CHANNELS[0], frames_out, kernel_size=1)])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, 3·frames_in, H, W) -> (B, frames_out, H, W)`` logits."""
        check_input(x, 3 * self.frames_in, "WASB")
        x = self.relu(self.bn1(self.conv1(x)))
        x = self.relu(self.bn2(self.conv2(x)))
        ys = [self.layer1(x)]
        stages = [(self.transition1, self.stage2), (self.transition2, self.stage3), (self.transition3, self.stage4)]
        for i, (trans, stage) in enumerate(stages):
            # existing branches take their own output; the new one branches off the lowest resolution
            xs = [t(ys[min(k, len(ys) - 1)]) for k, t in enumerate(trans)]
            last = i == len(stages) - 1
            ys = stage[0](xs, num_outputs=1 if last else None)
        return self.final_layers[0](ys[0])
