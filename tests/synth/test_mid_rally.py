"""Clips cut mid-rally (``SynthConfig(mid_rally=True)``, ``rally3d synth --mid-rally``): the same rally seen
from a frame inside a flight after the serve."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from synth.generate import SynthConfig, SynthScene, mid_rally_start
from synth.groundtruth import ball_3d_table, event_table

CONFIG = SynthConfig(sport="padel", camera="padel_tv", venue="tour", fps=25.0, width=640, height=360)


@pytest.mark.parametrize("seed", [2, 8])
def test_a_mid_rally_clip_is_the_same_rally_from_a_frame_inside_a_flight(seed):
    whole = SynthScene.build(seed, CONFIG).rally
    cut = SynthScene.build(seed, replace(CONFIG, mid_rally=True)).rally
    start = whole.n_frames - cut.n_frames
    hits = [c.t for c in whole.contacts if c.in_rally and c.player is not None]
    assert len(hits) >= 3 and hits[1] * whole.fps < start < hits[2] * whole.fps   # inside the 2nd flight
    assert start == mid_rally_start(whole, np.random.default_rng([seed, 13]))
    # no serve in the clip; every later contact kept, one start earlier
    assert cut.t_serve is None and cut.rally_frames() is None
    ev_whole, ev_cut = event_table(whole), event_table(cut)
    later = ev_whole.frame >= start
    np.testing.assert_array_equal(ev_cut.frame, ev_whole.frame[later] - start)
    np.testing.assert_array_equal(ev_cut.event, ev_whole.event[later])
    assert ev_cut.event[0] != "player_near" or ev_cut.frame[0] > 0
    # the ball is in flight at the clip's first frame, where the whole rally had it
    b_whole, b_cut = ball_3d_table(whole), ball_3d_table(cut)
    assert b_cut.frame[0] == 0 and b_cut.xyz[0, 2] > 0.05
    np.testing.assert_allclose(b_cut.xyz, b_whole.xyz[np.isin(b_whole.frame, b_cut.frame + start)], atol=1e-9)
    # the players stand where they stood
    for p_whole, p_cut in zip(whole.players, cut.players):
        np.testing.assert_allclose(p_cut.root, np.asarray(p_whole.root)[start:])
        np.testing.assert_allclose(p_cut.t, np.arange(cut.n_frames) / cut.fps, atol=1e-9)


def test_a_rally_with_fewer_than_two_hits_is_not_cut():
    whole = SynthScene.build(3, CONFIG).rally
    first_hit = next(c for c in whole.contacts if c.player is not None)
    short = replace(whole, contacts=[c for c in whole.contacts if c.player is None or c is first_hit])
    assert mid_rally_start(short, np.random.default_rng(0)) == 0
