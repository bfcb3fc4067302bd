"""rally3d inference: the runtime library (courts, camera calibration, clip I/O, models, detection and
tracking, hit events, players, 3D reconstruction, the pipeline and the ``rally3d`` CLI).

It depends on no other rally3d package.
"""
__version__ = "0.1.0"
