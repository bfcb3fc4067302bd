"""``data.tour``: a share of the simulated training rallies played at a tour final's pace."""
from __future__ import annotations

import pytest

from training.events.data.datamodule import EventDataModule


def test_tour_share_adds_tour_rallies_and_keeps_the_club_ones(tmp_path):
    club = EventDataModule(sport="tennis", class_set="tennis4", n_train=2, n_val=1, n_test=1, seed=5,
                           cache_dir=str(tmp_path)).raw_clips("train")
    mixed = EventDataModule(sport="tennis", class_set="tennis4", n_train=4, n_val=1, n_test=1, seed=5, tour=0.5,
                            cache_dir=str(tmp_path)).raw_clips("train")
    assert len(mixed) == 4
    assert [c.name for c in mixed[:2]] == [c.name for c in club]  # the club part is the same rallies
    assert not {c.name for c in mixed[2:]} & {c.name for c in club}  # the tour part: other seeds


def test_tour_share_is_refused_where_the_sport_has_no_tour_pace():
    with pytest.raises(ValueError, match="data.tour: no tour rally configuration for sport 'padel'"):
        EventDataModule(sport="padel", class_set="padel6", tour=0.5)
    with pytest.raises(ValueError, match=r"data.tour must be a fraction"):
        EventDataModule(sport="tennis", class_set="tennis4", tour=1.5)


def test_tour_rallies_are_filmed_by_the_tour_camera_when_told(tmp_path):
    """``data.tour_camera``: the tour-pace rallies come through that preset (a tour broadcast's long lens far
    behind the baseline), the club ones through the sport's default camera; an unknown preset is refused."""
    dm = EventDataModule(sport="tennis", class_set="tennis4", n_train=4, n_val=1, n_test=1, seed=5, tour=0.5,
                         tour_camera="tennis_tv", cache_dir=str(tmp_path))
    clips = dm.raw_clips("train")
    behind = [-float(c.camera.centre[1]) for c in clips]  # metres behind the near baseline
    assert all(b < 16.0 for b in behind[:2])          # tennis_broadcast: 14 ± 0.6 m
    assert all(17.5 <= b <= 40.5 for b in behind[2:])  # tennis_tv: 18–40 m
    with pytest.raises(ValueError, match="data.tour_camera: .*unknown camera preset 'tennis_blimp'"):
        EventDataModule(sport="tennis", class_set="tennis4", tour=0.5, tour_camera="tennis_blimp")
