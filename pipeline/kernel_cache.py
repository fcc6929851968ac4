"""The folder of compiled simulation kernels, kept to a bounded size.

:mod:`pipeline.simulate` writes one module ``k_<key>.py`` per model structure (``key``: 16 hex digits of
the SHA-256 of its source) and numba caches its machine code beside it in ``__pycache__/k_<key>.*``
(about 0.2 MB per structure). A user who diagnoses many different models would otherwise fill the
folder without limit (a development machine held 525 kernels, 107 MB, after a few weeks). Here:

* each load of a kernel marks it used (:func:`mark_used`: the file ``k_<key>.used``; not the module's
  own time stamp, which numba's cache index records and would treat as a changed source);
* once per process, before the first kernel is loaded, :func:`prune` removes the least recently used
  kernels beyond ``MAX_KERNELS`` (each kernel's files together), never one used in the last
  ``MIN_AGE_S`` seconds: a kernel another process is loading right now is fresh, so a prune never takes
  a file from under it, and the folder holds at most ``MAX_KERNELS`` kernels plus those of the last hour.

Only files this module's naming describes are removed (``k_<16 hex digits>.py``, ``.used`` and, in
``__pycache__``, names starting ``k_<16 hex digits>.``); anything else in the folder is left alone. A
removed kernel is compiled again when a model needs it (seconds, once).
"""

from __future__ import annotations

import os
import re
import threading
import time
from pathlib import Path

MAX_KERNELS = 300       # kernels kept (about 60 MB) beyond those used in the last MIN_AGE_S
MIN_AGE_S = 3600.0      # a kernel used this recently is never removed

_KEY = re.compile(r"^k_([0-9a-f]{16})\.py$")
_FILE_OF = re.compile(r"^k_([0-9a-f]{16})\.")
_PRUNED: set[str] = set()
_LOCK = threading.Lock()


def mark_used(folder: Path, key: str) -> None:
    """Record that kernel ``key`` was loaded now (create or touch ``k_<key>.used``); a folder that
    refuses the write only loses the record (the kernel may then be pruned earlier)."""
    try:
        (folder / f"k_{key}.used").touch()
    except OSError:
        pass


def _last_used(folder: Path, key: str) -> float | None:
    """When kernel ``key`` was last loaded (its ``.used`` mark, else its module's time); None when its
    module is gone."""
    for name in (f"k_{key}.used", f"k_{key}.py"):
        try:
            return (folder / name).stat().st_mtime
        except OSError:
            continue
    return None


def prune(folder: Path, max_kernels: int = MAX_KERNELS, min_age_s: float = MIN_AGE_S,
          now: float | None = None) -> list[str]:
    """Remove the least recently used kernels of ``folder`` beyond ``max_kernels``, none used in the last
    ``min_age_s`` seconds; returns the keys removed (oldest first). Files that vanish meanwhile (another
    process pruning too) or cannot be removed are skipped."""
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    keys = [m.group(1) for m in map(_KEY.match, names) if m]
    if len(keys) <= max_kernels:
        return []
    now = time.time() if now is None else now
    used = [(t, k) for k in keys if (t := _last_used(folder, k)) is not None]
    used.sort()
    removable = [k for t, k in used[:max(len(used) - max_kernels, 0)] if now - t >= min_age_s]
    if not removable:
        return []
    gone = set(removable)
    cache = folder / "__pycache__"
    try:
        compiled = [n for n in os.listdir(cache) if (m := _FILE_OF.match(n)) and m.group(1) in gone]
    except OSError:
        compiled = []
    for path in [folder / f"k_{k}.py" for k in removable] + [folder / f"k_{k}.used" for k in removable] \
            + [cache / n for n in compiled]:
        try:
            path.unlink()
        except OSError:
            pass
    return removable


def prune_once(folder: Path) -> None:
    """:func:`prune` the first time this process loads a kernel from ``folder``."""
    name = str(folder)
    if name in _PRUNED:
        return
    with _LOCK:
        if name not in _PRUNED:
            _PRUNED.add(name)
            prune(folder, MAX_KERNELS, MIN_AGE_S)
