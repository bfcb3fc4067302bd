"""The hit-event models' Lightning modules: HitNet, the event tagger, the crop model, the random forest."""
