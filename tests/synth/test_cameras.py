"""Camera presets: the tour broadcast's tennis camera stands for the range of real ones, the others are unchanged."""
from __future__ import annotations

import numpy as np

from inference.court import load_court
from synth.cameras import CameraSpec


def _rows(cam, points):
    return cam.project(np.asarray(points, float))[:, 1] / cam.image_size[1]


def test_tennis_tv_draws_long_lenses_far_behind_and_frames_the_run_off():
    """``tennis_tv`` draws a camera 18–40 m behind the near baseline at a 10–19° depression, higher the farther
    back, and frames the court with its run-off as the real broadcasts do (far baseline in the upper third,
    near baseline at about three quarters of the height, 1.5 m behind it and a player 4 m behind the far one in
    the picture);
    ``tennis_broadcast`` stays where it was (14 m behind) and shows the near baseline much lower."""
    court, rng = load_court("tennis"), np.random.default_rng(3)
    behind, depression, near, far = [], [], [], []
    for _ in range(40):
        spec = CameraSpec.preset("tennis_tv").randomised(rng)
        cam = spec.build(court)
        c = cam.centre
        behind.append(-c[1])
        depression.append(np.degrees(np.arctan2(c[2], np.hypot(*(np.asarray(spec.target[:2]) - c[:2])))))
        r = _rows(cam, [[5.485, 0, 0], [5.485, 23.77, 0], [5.485, -1.5, 0.0], [5.485, 27.77, 1.0]])
        near.append(r[0])
        far.append(r[1])
        assert 0.0 < r[3] < r[1] < r[0] < r[2] < 1.0  # the run-offs in the picture
    assert 17.9 <= min(behind) and max(behind) <= 40.1 and np.ptp(behind) > 12
    assert 9.9 <= min(depression) and max(depression) <= 19.1
    assert 0.2 <= np.median(far) <= 0.4 and 0.65 <= np.median(near) <= 0.85
    assert np.corrcoef(behind, [f for f in far])[0, 1] < 0.5  # framing not tied to the distance alone
    close = CameraSpec.preset("tennis_broadcast").build(court)
    assert abs(close.centre[1] + 14.0) < 1e-6 and _rows(close, [[5.485, 0, 0]])[0] > 0.85


def test_randomising_a_preset_without_a_spread_draws_as_before():
    """The other presets draw the same cameras as before the spread fields existed (the embedded sample and
    cached simulations depend on it): eye and aim jitter ``jitter_m`` per axis, no run-off."""
    spec = CameraSpec.preset("padel_broadcast")
    a = spec.randomised(np.random.default_rng(11))
    rng = np.random.default_rng(11)
    eye = np.asarray(spec.eye) + rng.uniform(-1, 1, 3) * np.array([0.9, 0.6, 0.6])
    target = np.asarray(spec.target) + rng.uniform(-1, 1, 3) * np.array([0.3, 0.6, 0.0])
    assert np.allclose(a.eye, eye) and np.allclose(a.target, target)
    assert a.run_off == (0.0, 0.0, 0.0) and a.eye_spread is None and a.elevation_deg is None
