"""What the hit-event models learn from: the data module, windows and crops, external datasets."""
