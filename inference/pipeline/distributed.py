"""Many videos on every core, and on many machines: ``rally3d infer … --workers N`` / ``--cluster ADDRESS``.

Each input (a clip folder, a video, a whole match) is one task of `Dask distributed
<https://distributed.dask.org>`_: ``--workers N`` starts a local cluster of N worker processes on this machine
(one task each at a time); ``--cluster tcp://HOST:8786`` sends the tasks to a running Dask scheduler, whose
workers may sit on other machines (``dask scheduler`` on one, ``dask worker tcp://HOST:8786 --nworkers 2
--nthreads 1`` on each; every machine must see the inputs and the output folder at the same paths, e.g. one
network share). A task is :func:`run_item`: exactly what one process runs for that input, so the results are
those of the single-process run (the same code on the same files; each worker sets torch to
``threads`` threads). A failing input is reported and the others go on. Why Dask rather than Ray: pure-Python
wheels of a few MB from the package registry, a local cluster in two lines (the test starts one), the
``dask scheduler`` / ``dask worker`` commands; a clip is a coarse task (seconds to hours) that needs no actors,
object store or GPU scheduling of its own (docs/pipeline.md, "Many videos, many machines").

Example:
    >>> results = run_items([(Path("a.mp4"), Path("out/a"))], cfg, court="padel", workers=2)
"""
from __future__ import annotations

import logging
import os
import sys
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path


@dataclass(frozen=True)
class ItemJob:
    """What a worker needs for one input (plain values: sent to other machines).

    Attributes:
        source, dest: the input and its output folder (None: the command's default).
        court, camera, court_points: as ``rally3d infer``'s options.
        only: the stages to run (None: all); match: split into rallies (True/False; None: by the video's length).
        match_params: :class:`~inference.pipeline.match.MatchParams` as a dict.
        threads: torch threads in the worker (0: leave torch's default).
    """

    source: str
    dest: str | None
    court: str | None = None
    camera: str | None = None
    court_points: str | None = None
    only: tuple[str, ...] | None = None
    match: bool | None = None
    match_params: dict | None = None
    threads: int = 1


def run_item(job: ItemJob, cfg_dict: dict) -> dict:
    """Run one input to the end in this process; a summary dict (``input``, ``clip``, ``ok``, ``table`` or
    ``error``, ``seconds``, ``host``). Never raises for a bad input."""
    import socket

    from .stages import PipelineConfig

    t0 = time.perf_counter()
    out = {"input": job.source, "host": socket.gethostname(), "pid": os.getpid()}
    if job.threads > 0:
        import torch

        torch.set_num_threads(job.threads)
    cfg = PipelineConfig(**{**cfg_dict, "progress": False,
                            **{k: Path(v) for k, v in cfg_dict.items() if k in _PATHS and v is not None}})
    source = Path(job.source)
    only = set(job.only) if job.only is not None else None
    try:
        if not source.exists():
            raise FileNotFoundError(f"{source}: not found on {out['host']} (every worker must see the inputs at "
                                    "the same path: a shared folder)")
        if _is_match_job(job, source):
            from .match import MatchIndex, MatchParams, run_match

            dest = Path(job.dest) if job.dest else Path("runs/infer") / source.stem
            code = run_match(source, dest, job.court, cfg, camera=_p(job.camera), court_points=_p(job.court_points),
                             params=MatchParams(**(job.match_params or {})), only=only, quiet=True)
            index = MatchIndex.read(dest / "match.json")
            out.update(clip=str(dest), ok=code == 0, table=index.summary())
        else:
            from .prepare import prepare
            from .run import run_pipeline

            prepared = prepare(source, _p(job.dest), job.court, _p(job.camera), _p(job.court_points))
            report = run_pipeline(prepared.clip, cfg, only=only, log=lambda *_: None)
            out.update(clip=str(prepared.clip.root), ok=report.ok, table=report.table(),
                       stages=[asdict(s) for s in report.stages])
    except (OSError, ValueError, RuntimeError) as e:
        out.update(ok=False, error=f"{type(e).__name__}: {e}")
    out["seconds"] = time.perf_counter() - t0
    return out


_PATHS = ("detector_weights", "events", "pose_model")


def _p(v: str | None) -> Path | None:
    return None if v is None else Path(v)


def _is_match_job(job: ItemJob, source: Path) -> bool:
    from .match import is_long_video

    return bool(job.match) if job.match is not None else is_long_video(source)


def config_dict(cfg) -> dict:
    """A :class:`~inference.pipeline.stages.PipelineConfig` as plain values (paths as strings)."""
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in asdict(cfg).items()}


def run_items(jobs: list[ItemJob], cfg, *, workers: int | None = None, address: str | None = None,
              log=None) -> list[dict]:
    """Run every job on a Dask cluster: a local one of ``workers`` processes, or the scheduler at ``address``.
    One progress line per input done (inputs done, the last one's result, time left); results in input order."""
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:  # pragma: no cover - a dependency of the project
        raise RuntimeError("--workers/--cluster need Dask distributed: pip install 'dask[distributed]'") from None
    from .match import duration

    log = log or (lambda msg: print(msg, file=sys.stderr, flush=True))
    cfg_dict = config_dict(replace(cfg, progress=False))
    cluster = None
    if address:
        client = Client(address, timeout="30s")
        where = f"the Dask scheduler at {address}"
    else:
        n = max(1, int(workers or 1))
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None,
                               silence_logs=logging.ERROR)
        client = Client(cluster)
        where = f"a local Dask cluster of {n} worker process{'es' if n > 1 else ''}"
    try:
        n_workers = len(client.scheduler_info().get("workers", {}))
        log(f"rally3d infer: {len(jobs)} inputs on {where} ({n_workers} workers)")
        futures = {client.submit(run_item, job, cfg_dict, pure=False, key=f"rally3d-{k}-{Path(job.source).name}"): k
                   for k, job in enumerate(jobs)}
        results: list[dict | None] = [None] * len(jobs)
        t0, done = time.perf_counter(), 0
        for fut in as_completed(futures):
            k = futures[fut]
            try:
                results[k] = fut.result()
            except Exception as e:  # noqa: BLE001 - a worker lost or killed: reported, the others go on
                results[k] = {"input": jobs[k].source, "ok": False, "error": f"{type(e).__name__}: {e}"}
            done += 1
            r = results[k]
            rate = done / (time.perf_counter() - t0)
            left = (len(jobs) - done) / rate if rate > 0 else float("nan")
            log(f"[{done}/{len(jobs)}] {r['input']}: {'ok' if r.get('ok') else 'INCOMPLETE'}"
                f"{' on ' + r['host'] if r.get('host') else ''}; ETA {duration(left) if left == left else '?'}")
        return [r for r in results if r is not None]
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
