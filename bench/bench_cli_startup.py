"""Benchmark the start-up of the ``rally3d`` command: CPU seconds (user + system) of ``rally3d --help``,
``rally3d <command> --help`` for every registered command, and the light commands ``courts`` and
``check`` on the sample clip. Each is a fresh interpreter (a subprocess); the median of ``--repeat`` runs is
printed as Markdown. CPU time, not wall time, so that other work on the machine does not skew it.

    .venv/bin/python bench/bench_cli_startup.py [--repeat 5] [--root .]

``--root`` measures another checkout of the project (its modules come first on the path; the commands are
the entry points installed in this interpreter's environment). Baselines: ``python -c pass`` and the
entry-point scan alone.
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
from importlib.metadata import entry_points
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
GROUP = "rally3d.commands"
SAMPLE = Path("datasets") / "sample" / "padel_sample"


def cpu_seconds(argv: list[str], root: Path, repeat: int) -> float:
    """Median CPU seconds (user + sys) of ``python argv`` run ``repeat`` times with ``root`` first on the path."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(root), os.environ.get("PYTHONPATH", "")])}
    times = []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        subprocess.run([sys.executable, *argv], cwd=root, env=env, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL, check=False)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        times.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return statistics.median(times)


def cases(root: Path) -> list[tuple[str, list[str]]]:
    cli = ["-m", "inference.cli"]
    out = [("python -c pass (interpreter alone)", ["-c", "pass"]),
           ("entry-point scan alone", ["-c", f"from importlib.metadata import entry_points; "
                                             f"entry_points(group={GROUP!r})"]),
           ("rally3d --help", [*cli, "--help"])]
    out += [(f"rally3d {ep.name} --help", [*cli, ep.name, "--help"])
            for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name)]
    out += [("rally3d courts", [*cli, "courts"])]
    if (root / SAMPLE).is_dir():
        out += [(f"rally3d check {SAMPLE}", [*cli, "check", str(SAMPLE)])]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=5, help="runs per command; the median is shown (default 5)")
    ap.add_argument("--root", type=Path, default=ROOT, help="the checkout to measure (default: this one)")
    args = ap.parse_args()
    root = args.root.resolve()
    print(f"CPU seconds (user + sys), median of {args.repeat} fresh processes; code from {root}\n")
    print("| command | CPU s |\n|---|---:|")
    for name, argv in cases(root):
        print(f"| `{name}` | {cpu_seconds(argv, root, args.repeat):.2f} |", flush=True)


if __name__ == "__main__":
    main()
