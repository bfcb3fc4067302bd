"""Comparisons of the hit-event models behind the documentation's tables."""
