"""Console progress on stderr: one line per stage, a bar where a stage loops.

API (tiny on purpose)::

    with stage("structures") as st:          # [structures] ...
        for item in bar(items, len(items), "fit"):   # [structures] fit  3/10 (1.2 s)  at most every ~1 s
            ...
        st.count(len(items))                 # [structures] done (10 items, 4.2 s)

A stage that runs longer than ``HEARTBEAT_S`` without printing gets a ``... still running (n s)`` line
from a background timer, so the console is never silent for more than ~2 s.

Output goes to stderr only and never into a run folder, so it cannot affect byte-identical outputs.
It is silent when ``SYSID_PROGRESS=0``, and under pytest (``PYTEST_CURRENT_TEST`` set) unless
``SYSID_PROGRESS=1`` or :func:`enable` is called.
"""

from __future__ import annotations

import contextlib
import os
import sys
import threading
import time
from collections.abc import Iterable, Iterator
from typing import IO, TypeVar

T = TypeVar("T")

HEARTBEAT_S = 2.0       # longest silence inside a stage
BAR_INTERVAL_S = 1.0    # a bar prints at most this often (plus its last line)
_WIDTH = 24

_forced: bool | None = None
_stream: IO[str] | None = None
_lock = threading.Lock()
_local = threading.local()
_last_print = [0.0]


def enable(on: bool | None = True, stream: IO[str] | None = None) -> None:
    """Force progress on (True), off (False) or back to automatic (None); optionally redirect it."""
    global _forced, _stream
    _forced, _stream = on, stream


@contextlib.contextmanager
def silenced() -> Iterator[None]:
    """No progress lines inside the block (a batch worker; the batch prints its own)."""
    global _forced
    old, _forced = _forced, False
    try:
        yield
    finally:
        _forced = old


def enabled() -> bool:
    if _forced is not None:
        return _forced
    env = os.environ.get("SYSID_PROGRESS")
    if env is not None:
        return env not in ("0", "", "false", "no")
    return "PYTEST_CURRENT_TEST" not in os.environ


def emit(line: str) -> None:
    """Print one progress line (no-op when disabled)."""
    if not enabled():
        return
    out = _stream if _stream is not None else sys.stderr
    with _lock:
        print(line, file=out, flush=True)
        _last_print[0] = time.monotonic()


def _fmt_s(s: float) -> str:
    return f"{s:.1f} s"


class Stage:
    """A running stage: ``count(n)`` sets the item count shown on the closing line."""

    def __init__(self, name: str, total: int | None = None):
        self.name, self.total, self.items = name, total, total
        self.t0 = time.monotonic()
        self._stop = threading.Event()
        self._timer: threading.Thread | None = None

    def count(self, n: int) -> None:
        self.items = n

    def elapsed(self) -> float:
        return time.monotonic() - self.t0

    def _heartbeat(self) -> None:
        while not self._stop.wait(0.25):
            if time.monotonic() - _last_print[0] >= HEARTBEAT_S:
                emit(f"[{self.name}] ... still running ({_fmt_s(self.elapsed())})")

    def start(self) -> "Stage":
        what = f" ({self.total} items)" if self.total is not None else ""
        emit(f"[{self.name}] ...{what}")
        if enabled():
            self._timer = threading.Thread(target=self._heartbeat, daemon=True)
            self._timer.start()
        return self

    def finish(self, ok: bool | str = True) -> None:
        """``ok``: True (done), False (failed) or the word to print instead (``"interrupted"``)."""
        self._stop.set()
        if self._timer is not None:
            self._timer.join(timeout=1.0)
        n = f"{self.items} items, " if self.items is not None else ""
        word = ok if isinstance(ok, str) else ("done" if ok else "failed")
        emit(f"[{self.name}] ... {word} ({n}{_fmt_s(self.elapsed())})")


@contextlib.contextmanager
def stage(name: str, total: int | None = None) -> Iterator[Stage]:
    """Print ``[name] ...`` now and ``[name] ... done (n items, 1.2 s)`` at the end; nested bars use
    ``name`` as their prefix."""
    st = Stage(name, total).start()
    stack = getattr(_local, "stack", None)
    if stack is None:
        stack = _local.stack = []
    stack.append(st)
    ok: bool | str = False
    try:
        yield st
        ok = True
    except KeyboardInterrupt:
        ok = "interrupted"       # Ctrl-C, not a failure of the stage
        raise
    finally:
        stack.pop()
        st.finish(ok)


def _current() -> Stage | None:
    stack = getattr(_local, "stack", None)
    return stack[-1] if stack else None


def bar(iterable: Iterable[T], total: int | None = None, label: str = "", always_final: bool = True) -> Iterator[T]:
    """Yield from ``iterable``, printing ``[stage] label [####....] k/total (t s)`` at most every
    ``BAR_INTERVAL_S`` and once at the end (with ``always_final=False`` only when the loop took longer
    than ``BAR_INTERVAL_S``: inner loops that are usually fast). Counts the items into the enclosing
    stage."""
    if total is None:
        try:
            total = len(iterable)  # type: ignore[arg-type]
        except TypeError:
            total = None
    st = _current()
    prefix = f"[{st.name}] " if st else ""
    t0 = time.monotonic()
    last = t0
    k = 0
    for item in iterable:
        yield item
        k += 1
        now = time.monotonic()
        if now - last >= BAR_INTERVAL_S and (total is None or k < total):
            last = now
            emit(f"{prefix}{label} {_bar_text(k, total)} ({_fmt_s(now - t0)})")
    if st is not None and st.items is None:  # the stage's first loop gives its item count
        st.count(k)
    if always_final or time.monotonic() - t0 >= BAR_INTERVAL_S:
        emit(f"{prefix}{label} {_bar_text(k, total)} ({_fmt_s(time.monotonic() - t0)})")


def _bar_text(k: int, total: int | None) -> str:
    if not total:
        return f"{k}"
    filled = int(round(_WIDTH * min(k, total) / total))
    return f"[{'#' * filled}{'.' * (_WIDTH - filled)}] {k}/{total}"
