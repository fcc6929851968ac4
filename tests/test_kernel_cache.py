"""The kernel cache folder stays bounded: least recently used kernels beyond the cap are removed, with
their compiled files, never one used in the last hour, and never a file of another name."""

import os
import re
import time

from pipeline import kernel_cache, simulate
from pipeline.expressions import parse
from pipeline.model import Model


def _kernel(folder, key: str, used_age: float | None, module_age: float, now: float) -> None:
    """A fake kernel ``key``: its module, numba's two cache files and Python's bytecode, last used
    ``used_age`` seconds before ``now`` (no mark when None: the module's own time counts)."""
    (folder / "__pycache__").mkdir(exist_ok=True)
    files = [folder / f"k_{key}.py", folder / "__pycache__" / f"k_{key}.simulate-43.py311.nbi",
             folder / "__pycache__" / f"k_{key}.simulate-43.py311.1.nbc",
             folder / "__pycache__" / f"k_{key}.cpython-311.pyc"]
    for f in files:
        f.write_text(kernel_cache.HEADER + " for states ['x']; do not edit\n" if f.suffix == ".py" else "x")
        os.utime(f, (now - module_age, now - module_age))
    if used_age is not None:
        u = folder / f"k_{key}.used"
        u.write_text("")
        os.utime(u, (now - used_age, now - used_age))


def _keys(folder) -> set[str]:
    return {n[2:18] for n in os.listdir(folder) if re.fullmatch(r"k_[0-9a-f]{16}\.py", n)}


def test_prune_removes_the_least_recently_used_beyond_the_cap_and_nothing_else(tmp_path):
    now = 2_000_000_000.0
    day = 86400.0
    keys = [f"{i:016x}" for i in range(8)]
    # last used 8, 7, ..., 1 days ago; kernel 0 has an old module but was used a minute ago
    for i, k in enumerate(keys):
        _kernel(tmp_path, k, used_age=60.0 if i == 0 else (9 - i) * day, module_age=30 * day, now=now)
    foreign = [tmp_path / "notes.txt", tmp_path / "k_short.py", tmp_path / "k_0000000000000001.py.bak",
               tmp_path / "__pycache__" / "other.cpython-311.pyc", tmp_path / "k_ffffffffffffff00.py"]
    for f in foreign:
        f.write_text("not the tool's")
    # a module of the kernels' name that the tool did not write, the least recently used of all
    os.utime(tmp_path / "k_ffffffffffffff00.py", (now - 90 * day, now - 90 * day))
    removed = kernel_cache.prune(tmp_path, max_kernels=3, min_age_s=3600.0, now=now)
    # oldest first: used 8, 7, 6, 5, 4 days ago; the three most recent (1 min, 1 day, 2 days) stay
    assert removed == keys[1:6]
    assert _keys(tmp_path) == {keys[0], keys[6], keys[7], "ffffffffffffff00"}
    left = os.listdir(tmp_path / "__pycache__")
    assert not any(k in n for n in left for k in removed)
    assert sum(keys[0] in n for n in left) == 3
    assert all(f.exists() for f in foreign)
    assert not any((tmp_path / f"k_{k}.used").exists() for k in removed)


def test_prune_never_removes_a_kernel_used_in_the_last_hour(tmp_path):
    now = time.time()
    keys = [f"{i:016x}" for i in range(6)]
    for i, k in enumerate(keys):       # all used within the hour: the cap is exceeded, nothing goes
        _kernel(tmp_path, k, used_age=100.0 * (i + 1), module_age=100.0 * (i + 1), now=now)
    assert kernel_cache.prune(tmp_path, max_kernels=2, min_age_s=3600.0, now=now) == []
    assert _keys(tmp_path) == set(keys)
    # a kernel without a use mark counts from its module's time
    _kernel(tmp_path, "ffffffffffffffff", used_age=None, module_age=5 * 3600.0, now=now)
    assert kernel_cache.prune(tmp_path, max_kernels=2, min_age_s=3600.0, now=now) == ["ffffffffffffffff"]
    assert kernel_cache.prune(tmp_path, max_kernels=10, min_age_s=0.0, now=now) == []


def test_loading_a_kernel_prunes_the_folder_once_and_marks_the_kernel_used(tmp_path, monkeypatch):
    """Through the simulator: the first load of a process from a folder prunes it (here to 2 kernels:
    the 5 stale ones go down to 2), then writes the new kernel and marks it used. Loading defines the
    numba functions without compiling them (they compile on their first call), so this is quick."""
    folder = tmp_path / "cache" / "kernels"
    folder.mkdir(parents=True)
    now = time.time()
    stale = [f"{i:016x}" for i in range(5)]
    for i, k in enumerate(stale):
        _kernel(folder, k, used_age=(10 - i) * 86400.0, module_age=30 * 86400.0, now=now)
    monkeypatch.setenv("SYSID_KERNEL_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(kernel_cache, "MAX_KERNELS", 2)
    m = Model(states=("x",), inputs=("u",), equations={"x": parse("-a*x + u", {"x", "u", "a"})},
              output_exprs={}, params={"a": 1.0}, free=(), initial={"x": 0.0}, nominal_params=("a",))
    src = simulate.kernel_source(m)
    key = "a" * 16
    fns = simulate._load_kernel(key, src)
    assert len(fns) == 3 and all(callable(f) for f in fns)
    assert _keys(folder) == {stale[3], stale[4], key}
    assert (folder / f"k_{key}.used").exists()
    # once per process and folder: more stale kernels are not pruned by the next load
    _kernel(folder, "e" * 16, used_age=50 * 86400.0, module_age=50 * 86400.0, now=now)
    simulate._load_kernel("b" * 16, src)
    assert "e" * 16 in _keys(folder)
