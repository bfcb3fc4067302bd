"""The synthetic sample maker writes a valid clip whose ground truth is self-consistent."""
from __future__ import annotations

import numpy as np

from inference.clipio import Clip
from training.sample_clip import SampleSpec, make_sample_clip


def test_sample_clip_is_consistent(tmp_path):
    clip = make_sample_clip(tmp_path / "c", SampleSpec(n_frames=40, seed=3))
    info = clip.info
    assert (info.width, info.height, info.n_frames) == (1280, 720, 40)
    frames = clip.frames()
    assert len(frames) == 40 and frames[10].shape == (720, 1280, 3)
    ball = clip.read_ball()
    gt = clip.read_ball_3d(gt=True)
    cam = clip.read_camera(gt=True)
    vis = ball.visibility == 1
    # the 2D labels are the projection of the 3D ground truth
    np.testing.assert_allclose(cam.project_normalized(gt.xyz)[vis], ball.xy[vis], atol=1e-6)
    # the ball is drawn where the label says: the pixel there is yellow-ish, not floor blue
    f = int(np.flatnonzero(vis)[5])
    x, y = np.round(ball.to_pixels(1280, 720)[f]).astype(int)
    r, g, b = frames[f][y, x].astype(int)
    assert r > 150 and g > 150 and b < 120
    # the ball bounces on the floor: the gt height touches the radius at the ground event
    events = clip.read_events(gt=True)
    ground = events.frame[events.event == "ground"]
    assert len(ground) >= 1
    assert gt.xyz[ground[0], 2] < 0.3
    pts = clip.read_court_points()
    assert len(pts.names) >= 20
