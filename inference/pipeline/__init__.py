"""The end-to-end pipeline ``rally3d infer``: video → ball, events, players, 3D in a clip folder.

Stages (:mod:`.stages`) run in order, resumably (:mod:`.state`), with a per-stage timing summary
(:mod:`.run`); many clips go through Lightning's predict loop (:mod:`.engine`).
"""
from .prepare import Prepared, prepare
from .run import PipelineReport, StageReport, run_pipeline
from .score import Scores, score
from .stages import PipelineConfig

__all__ = ["PipelineConfig", "PipelineReport", "Prepared", "Scores", "StageReport", "prepare", "run_pipeline",
           "score"]
