"""The ``rally3d`` command: a dispatcher over subcommands that packages register as entry points.

Each package declares its subcommands in ``pyproject.toml`` under the entry-point group
``rally3d.commands``; an entry point is a function ``register(subparsers)`` that adds one subparser and
sets ``func`` (called with the parsed namespace, returning an exit code). The dispatcher never imports
``training`` or ``labeler`` by name, so the package arrows stay one-way.
"""
from __future__ import annotations

import argparse
import os
import sys
from importlib.metadata import entry_points

GROUP = "rally3d.commands"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rally3d",
        description="3D replays of padel and tennis rallies from one fixed camera.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name):
        try:
            register = ep.load()
        except Exception as e:  # a broken optional package must not break the other commands
            print(f"rally3d: warning: command {ep.name!r} is unavailable ({type(e).__name__}: {e})",
                  file=sys.stderr)
            continue
        register(sub)
    return parser


def _subparser(parser: argparse.ArgumentParser, name: str | None) -> argparse.ArgumentParser | None:
    """The subparser of command ``name`` (None when unknown)."""
    for action in parser._subparsers._group_actions if parser._subparsers else []:
        if isinstance(action, argparse._SubParsersAction) and name in action.choices:
            return action.choices[name]
    return None


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, unknown = parser.parse_known_args(argv)
    if unknown:  # argparse would name the top-level usage; the subcommand's usage is the useful one
        sub = _subparser(parser, getattr(args, "command", None))
        (sub or parser).error(f"unrecognized arguments: {' '.join(unknown)}")
    if not getattr(args, "func", None):
        parser.print_help()
        return 0 if args.command is None else 2
    from inference.clipio.errors import FormatError  # after parsing: `--help` stays free of NumPy and OpenCV

    try:
        return int(args.func(args) or 0)
    except (FormatError, OSError, KeyError, ValueError, RuntimeError) as e:
        if os.environ.get("RALLY3D_DEBUG"):  # the traceback, for a bug report
            raise
        msg = e.args[0] if isinstance(e, KeyError) and e.args else e
        print(f"rally3d {args.command}: error: {msg}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
