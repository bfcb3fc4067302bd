"""The simulated source of the hit-event models: rallies without rendering, degraded like real tracks and poses."""
