"""The diagnosis' console lines on stderr (never in a run folder, so they cannot change its outputs)."""

import sys


def log(msg: str) -> None:
    print(f"[diagnose] {msg}", file=sys.stderr, flush=True)
