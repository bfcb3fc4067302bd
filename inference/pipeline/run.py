"""Run the stages of ``rally3d infer`` on one clip folder: resume, guard hand-made files, time each stage.

Example:
    >>> report = run_pipeline(Clip("runs/infer/rally"), PipelineConfig())
    >>> print(report.table()); report.ok
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from inference.clipio import Clip, FormatError
from inference.court import load_court

from .stages import Context, Outcome, PipelineConfig, Skip, Stage, StageError, build_stages
from .state import STATE_DIR, RunState, backup_file, stage_key

# the errors a stage reports as a failure of that stage (bad input), not as a crash of the program
STAGE_ERRORS = (StageError, FormatError, FileNotFoundError, ValueError, RuntimeError)


@dataclass
class StageReport:
    """One stage's line of the summary. status: done, cached, partial, skipped, failed, blocked or not run.
    seconds: wall time; cpu_seconds: the process's CPU time over the stage (every thread)."""

    name: str
    status: str
    seconds: float = 0.0
    frames: int = 0
    note: str = ""
    cpu_seconds: float = 0.0

    @property
    def fps(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 and self.frames else float("nan")


@dataclass
class PipelineReport:
    """The summary of one clip's run."""

    clip: Clip
    stages: list[StageReport] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        """True when every stage is done, cached, or skipped for an optional reason only (players)."""
        for s in self.stages:
            if s.status in ("failed", "blocked", "partial"):
                return False
            if s.status == "skipped" and s.name != "players":
                return False
        return True

    def table(self) -> str:
        """Per-stage timing summary (wall seconds, CPU seconds, frames/s) with the slowest stage marked."""
        ran = [s for s in self.stages if s.status in ("done", "partial") and s.seconds > 0]
        slowest = max(ran, key=lambda s: s.seconds).name if ran else None
        lines = [f"{'stage':<12} {'status':<8} {'seconds':>8} {'CPU s':>8} {'frames/s':>9}  note"]
        for s in self.stages:
            fps = f"{s.fps:9.1f}" if s.fps == s.fps else f"{'':>9}"
            mark = " ← slowest" if s.name == slowest else ""
            lines.append(f"{s.name:<12} {s.status:<8} {s.seconds:8.2f} {s.cpu_seconds:8.2f} {fps}  {s.note}{mark}")
        total = sum(s.seconds for s in self.stages)
        cpu = sum(s.cpu_seconds for s in self.stages)
        lines.append(f"{'total':<12} {'':<8} {total:8.2f} {cpu:8.2f}")
        return "\n".join(lines)


def _guard_outputs(stage: Stage, ctx: Context, outputs: list[Path]) -> None:
    """Never overwrite a file the pipeline did not write, unless --overwrite (then keep a backup)."""
    for path in outputs:
        if ctx.state.written_by_pipeline(path):
            continue
        if not ctx.cfg.overwrite:
            raise StageError(f"{path} exists and was not written by rally3d infer (hand annotations?) — pass "
                             "--out DIR to write the results elsewhere, or --overwrite to replace it "
                             f"(a backup is kept in {STATE_DIR}/backup/)")
        backup_file(ctx.clip.root, path)


def run_pipeline(clip: Clip, cfg: PipelineConfig | None = None, only: set[str] | None = None,
                 log=print) -> PipelineReport:
    """Run every stage on ``clip`` (skipping those whose inputs did not change); never raises on bad input.

    Args:
        clip: the clip folder (see :mod:`.prepare`).
        cfg: settings; only: run just these stages (the others count as cached if current).
        log: where progress lines go.
    """
    cfg = cfg or PipelineConfig()
    report = PipelineReport(clip)
    try:
        court = load_court(clip.court_path())
        clip.info  # noqa: B018 - validates clip.yaml early
    except STAGE_ERRORS as e:
        report.stages.append(StageReport("setup", "failed", note=str(e)))
        return report
    ctx = Context(clip, court, cfg, RunState(clip.root))
    status: dict[str, str] = {}
    for stage in build_stages():
        missing = [r for r in stage.requires if status.get(r) not in ("done", "cached", "partial", "not run")]
        if missing:
            status[stage.name] = "blocked"
            report.stages.append(StageReport(stage.name, "blocked", note=f"needs {', '.join(missing)}"))
            continue
        if only is not None and stage.name not in only:
            status[stage.name] = "not run"
            report.stages.append(StageReport(stage.name, "not run", note="not requested (--only)"))
            continue
        rep = _run_stage(stage, ctx, log)
        status[stage.name] = rep.status
        report.stages.append(rep)
    return report


def _run_stage(stage: Stage, ctx: Context, log) -> StageReport:
    """One stage's run with its wall and CPU time (a cached stage: 0)."""
    c0 = time.process_time()
    rep = _stage_report(stage, ctx, log)
    rep.cpu_seconds = time.process_time() - c0 if rep.status != "cached" else 0.0
    return rep


def _stage_report(stage: Stage, ctx: Context, log) -> StageReport:
    t0 = time.perf_counter()
    try:
        key = stage_key(stage.inputs(ctx), stage.params(ctx), stage.code)
        outputs = stage.outputs(ctx)
        if ctx.state.is_current(stage.name, key, outputs):
            rec = ctx.state.stages[stage.name]
            return StageReport(stage.name, "cached", 0.0, 0, rec.get("note", ""))
        _guard_outputs(stage, ctx, outputs)
        log(f"[{stage.name}] running")
        out: Outcome = stage.run(ctx)
    except Skip as e:
        return StageReport(stage.name, "skipped", time.perf_counter() - t0, note=str(e))
    except STAGE_ERRORS as e:
        msg = e.args[0] if isinstance(e, KeyError) and e.args else str(e)
        log(f"[{stage.name}] failed: {msg}")
        ctx.state.record(stage.name, "", "failed", [], time.perf_counter() - t0, msg)
        return StageReport(stage.name, "failed", time.perf_counter() - t0, note=msg)
    seconds = time.perf_counter() - t0
    status = "partial" if out.partial else "done"
    # a partial result (a truncated video) is kept but not cached: the next run retries the stage
    ctx.state.record(stage.name, key if status == "done" else "", status, outputs, seconds, out.note)
    return StageReport(stage.name, status, seconds, out.frames, out.note)
