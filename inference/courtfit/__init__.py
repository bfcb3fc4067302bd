"""Automatic court fitting: find the court's painted lines in a video and calibrate the camera from them.

Example:
    >>> fit = fit_court(Clip("runs/clip"), load_court("padel"))
    >>> fit.accepted, fit.confidence, fit.summary()
"""
from .fit import AutoFit, AutoFitError, fit_court, fit_court_frames, sample_frame_indices

__all__ = ["AutoFit", "AutoFitError", "fit_court", "fit_court_frames", "sample_frame_indices"]
