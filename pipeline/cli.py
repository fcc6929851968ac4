"""Command line: ``sysid report CONFIG [--out DIR]``, ``sysid diagnose CONFIG [--out DIR]`` and the
commands registered by other modules (``COMMAND_MODULES``).

Exit codes: 0 ok, 2 bad input (config, data, options: one message naming file and key), 1 internal
error. ``--out`` is the run folder itself (default ``reports/<run-id>``).

A command module exposes ``register(subparsers) -> dict[name, handler]``; a handler takes the parsed
``argparse.Namespace`` and returns the exit code. It raises :class:`pipeline.errors.InputError` for
bad input; :func:`main` turns that into one ``error:`` line and exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys
import traceback

# modules that add subcommands (each one file, one line here)
COMMAND_MODULES: list[str] = [
    "pipeline.assignment.cli",
    "pipeline.store_cli",
]


def _run_command(args: argparse.Namespace) -> int:
    from .runs import run
    path = run(args.config, args.out, html=args.cmd == "report", track=args.track)
    if args.cmd == "report":
        print(f"report: {path / 'report.html'}")
    else:
        print(f"run folder: {path}")
    return 0


def build_parser() -> tuple[argparse.ArgumentParser, dict]:
    ap = argparse.ArgumentParser(prog="sysid", description="What the simulation gets wrong, why, the fix "
                                 "and its worth.")
    from . import __version__
    ap.add_argument("--version", action="version", version=f"sysid {__version__}")
    sub = ap.add_subparsers(dest="cmd", required=True)
    handlers = {}
    for name, helptext in (("report", "run the pipeline and write the run folder with report.html"),
                           ("diagnose", "run the pipeline and write the run folder without the HTML")):
        p = sub.add_parser(name, help=helptext)
        p.add_argument("config", help="YAML config (see configs/demo.yaml)")
        p.add_argument("--out", help="run folder to write (default reports/<run-id>)")
        p.add_argument("--track", nargs="?", const="default", metavar="URI",
                       help="log the run to MLflow (default sqlite:///reports/mlruns.db; extra [mlflow])")
        handlers[name] = _run_command
    for modname in COMMAND_MODULES:
        handlers.update(importlib.import_module(modname).register(sub))
    return ap, handlers


def main(argv: list[str] | None = None) -> int:
    ap, handlers = build_parser()
    try:
        args = ap.parse_args(argv)
    except SystemExit as exc:  # argparse: usage errors are bad input
        return 2 if exc.code else 0
    os.environ.setdefault("MPLBACKEND", "Agg")
    from . import runfolder
    from .errors import InputError
    prev = _remember_interrupts(runfolder)
    try:
        return handlers[args.cmd](args)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted; no run folder written", file=sys.stderr)
        return 130      # 128 + SIGINT, the shell's code for a command stopped by Ctrl-C
    except Exception:
        traceback.print_exc()
        print("internal error: please report it with the traceback above", file=sys.stderr)
        return 1
    finally:
        if prev is not None:
            signal.signal(signal.SIGINT, prev)
        runfolder.INTERRUPTED.clear()


def _remember_interrupts(runfolder):
    """On Ctrl-C, mark the process interrupted (``runfolder.INTERRUPTED``) before raising
    KeyboardInterrupt as usual. Python drops an exception raised while a weakref or GC callback runs
    ("Exception ignored in ..."), so an interrupt could be lost and the run publish a folder after all;
    :func:`pipeline.runfolder.publish` checks the mark. Returns the previous handler (None off the main
    thread, where signals cannot be handled)."""
    def on_sigint(signum, frame):
        runfolder.INTERRUPTED.set()
        if not runfolder.DEFERRING.is_set():    # else the deferring code raises (runfolder.deferred_interrupts)
            signal.default_int_handler(signum, frame)
    try:
        return signal.signal(signal.SIGINT, on_sigint)
    except ValueError:
        return None


if __name__ == "__main__":
    sys.exit(main())
