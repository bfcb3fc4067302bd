"""Shared pieces of the detection tests (imported as ``from detection_helpers import ...``): a hand-made colour "network" and a clip renderer."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

BALL_BGR = (215, 232, 62)   # cv2 colour order: a yellow ball
COURT_BGR = (40, 70, 140)


class YellowNet(nn.Module):
    """Logits that are high where a frame is ball-coloured (R + G - 2B large), one map per input frame.
    A 1×1 convolution: fully convolutional, any input size."""

    def __init__(self, frames: int = 3):
        super().__init__()
        self.conv = nn.Conv2d(3 * frames, frames, 1)
        w = torch.zeros(frames, 3 * frames, 1, 1)
        for k in range(frames):
            w[k, 3 * k:3 * k + 3, 0, 0] = torch.tensor([1.0, 1.0, -2.0]) * 25
        self.conv.weight.data = w
        self.conv.bias.data.fill_(-25 * 0.75)

    def forward(self, x):
        return self.conv(x)


def render_clip(root: Path, xy: np.ndarray, size=(640, 360), fps: float = 30.0, still=((500, 320),)):
    """A clip folder whose video shows a yellow ball at ``xy (T, 2)`` px (NaN rows: no ball) and still yellow
    balls at ``still`` on a dark court; ``ball.csv`` holds the moving ball's ground truth (visibility 0 for NaN
    rows and positions outside the frame)."""
    import cv2

    from inference.clipio import BallTrack, Clip, ClipInfo, write_video

    w, h = size
    clip = Clip.create(root, ClipInfo(sport="padel", fps=fps, width=w, height=h, video="video.mp4",
                                      n_frames=len(xy)))
    frames = []
    for p in xy:
        img = np.full((h, w, 3), COURT_BGR, np.uint8)
        for s in still:
            cv2.circle(img, tuple(s), 5, BALL_BGR, -1, cv2.LINE_AA)
        if np.all(np.isfinite(p)):
            cv2.circle(img, tuple(np.round(p).astype(int)), 5, BALL_BGR, -1, cv2.LINE_AA)
        frames.append(img)
    write_video(clip.video_path, frames, fps)
    seen = np.all(np.isfinite(xy) & (xy >= 0) & (xy <= [w, h]), axis=1)   # left the frame: no ball
    clip.write_ball(BallTrack(np.arange(len(xy)), seen.astype(np.int8), np.where(seen[:, None], xy / [w, h], np.nan)))
    return clip
