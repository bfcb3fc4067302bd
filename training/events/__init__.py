"""Training the hit-event models (the runtime side is :mod:`inference.events`).

- :mod:`.run` — the Hydra tasks (``task: events``): train, tune the decoder, test, export;
  :mod:`.evaluate` — decoder tuning, temperature calibration and event-set scores, shared by every model.
- :mod:`.models` — one Lightning module per model: HitNet (:mod:`.models.hitnet`), the event tagger
  (:mod:`.models.tagger`), the crop model (:mod:`.models.crop`, its tasks :mod:`.models.crop_run`), the thesis's
  random forest (:mod:`.models.rf`).
- :mod:`.data` — what they learn from: the data module and its windows (:mod:`.data.datamodule`), the
  tagger's clip crops (:mod:`.data.sequences`), the crop model's rendered clips (:mod:`.data.crop_data`),
  TrackNet ``Label.csv`` datasets (:mod:`.data.tracknet`), per-clip work on several processes
  (:mod:`.data.parallel`).
- :mod:`.synthetic` — the simulated source: rallies without rendering (:mod:`.synthetic.simulate`), made to
  look like a tracker's output (:mod:`.synthetic.degrade`) and a pose backend's (:mod:`.synthetic.pose_noise`).
- :mod:`.stats` — measurements that fit the synthetic source: real tracks (:mod:`.stats.real_stats`), the
  project's detector (:mod:`.stats.track_stats`), the players stage (:mod:`.stats.pose_stats`).
- :mod:`.studies` — comparisons behind the docs' tables (:mod:`.studies.compare`, :mod:`.studies.crop_compare`,
  :mod:`.studies.e2e`).
"""
