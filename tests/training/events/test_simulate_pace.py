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


def test_club_rallies_come_through_each_camera_in_its_share(tmp_path):
    """``data.cameras``: the club-pace rallies split over camera presets by share (a tour broadcast's high
    camera far behind the near glass beside a club's fixed one); wrong presets or shares are refused."""
    from training.events.data.datamodule import split_counts

    assert split_counts(5, {"a": 0.5, "b": 0.5}) == {"a": 3, "b": 2}
    assert sum(split_counts(7, {"a": 0.2, "b": 0.3, "c": 0.5}).values()) == 7
    dm = EventDataModule(sport="padel", class_set="padel6", n_train=4, n_val=1, n_test=1, seed=5,
                         cameras={"padel_installed": 0.5, "padel_tv": 0.5}, cache_dir=str(tmp_path))
    behind = [-float(c.camera.centre[1]) for c in dm.raw_clips("train")]  # metres behind the near glass
    assert all(b < 8.0 for b in behind[:2])            # padel_installed: right behind the glass
    assert all(b > 11.0 for b in behind[2:])           # padel_tv: 13.5 m behind
    for bad, match in (({"padel_blimp": 1.0}, "data.cameras: .*unknown camera preset 'padel_blimp'"),
                       ({"padel_tv": 0.5}, "add up to 0.5, not 1"),
                       ({"padel_tv": -1.0, "padel_installed": 2.0}, "data.cameras.padel_tv: a share must be a positive number"),
                       (["padel_tv"], "must map camera presets to shares")):
        with pytest.raises(ValueError, match=match):
            EventDataModule(sport="padel", class_set="padel6", cameras=bad)
