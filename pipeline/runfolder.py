"""Run folders that never destroy a user's files.

A run folder is written into a hidden temporary folder beside the target and published by renames,
so the final name never holds a partial run and nothing this tool did not create is ever removed.

**What a run folder is.** A folder holding the regular file ``.sysid-run`` (the *marker*), a JSON
object ``{"tool": "sysid-pipeline", "format": 2, "run_id": ..., "files": {relative path: {"size":
bytes, "sha256": hex}}}`` (format 1, written before, lists sizes only). The marker is written last,
after every other file has been written and flushed, so a folder with a valid marker whose listed files
all exist with the listed sizes is *complete* (what readers use), and it is *replaceable* only when it
holds nothing but those files, each with its listed content (sha256 in format 2): a user's added note,
or an edit that keeps a file's size, keeps it safe. Folders written by
releases before the marker existed are recognised too (:func:`is_legacy_run`): only regular files, all
with the names the old ``write_run`` wrote, with ``summary.json`` of schema ``sysid-summary/*`` and a
``manifest.json`` naming ``sysid-pipeline``.

**Names beside the target** (all hidden, so every reader that skips dot-names ignores them):

- ``.<name>.tmp-<pid>-<8 hex>``  the run being written (created with mode ``0o777 & ~umask``);
- ``.<name>.old-<pid>-<8 hex>``  the previous run, moved aside for the moment of the swap.

A later run into the same parent removes such folders once their pid is dead (or they are older
than a day, in case the pid was reused), and only when they are this tool's: a temp folder holds the
token file ``.sysid-tmp`` (created with it, removed when the run is finalized) and a moved-aside run its
marker (:func:`clean_stale`). A user's folder that merely has such a name is never touched.

**Publishing** (:func:`publish`) holds an exclusive ``fcntl.flock`` on the parent folder (or, where
a folder cannot be locked, on ``.<name>.lock`` beside the target), so concurrent runs of one config
publish one after another: a fresh or empty target takes one ``rename`` of the complete temp folder;
a complete earlier run is renamed aside, the new one renamed in, then the old one deleted.

**Checking** (:func:`check_target`) runs before the analysis and raises :class:`InputError` naming
``--out`` for every target that could not or must not be written, so a bad ``--out`` costs nothing.

Test hook: with the environment variable ``SYSID_TEST_KILL_AT`` set to one of :data:`KILL_POINTS`, the
process sends itself ``SIGKILL`` at that point (tests of crash safety; never set it otherwise).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import re
import secrets
import shutil
import signal
import stat
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from .errors import InputError
from .hashing import file_sha256

TOOL = "sysid-pipeline"
MARKER = ".sysid-run"
MARKER_FORMAT = 2
TMP_TOKEN = ".sysid-tmp"   # in a temp folder from its creation until finalize: this tool made it
INTERRUPTED = threading.Event()   # set by the CLI's SIGINT handler: never publish after a Ctrl-C
# while set, the CLI's SIGINT handler only sets INTERRUPTED and the code that set it raises
# KeyboardInterrupt itself (:func:`deferred_interrupts`)
DEFERRING = threading.Event()


@contextlib.contextmanager
def deferred_interrupts() -> Iterator[None]:
    """Within: a Ctrl-C under the CLI only marks the process ``INTERRUPTED``; the caller checks the mark
    (:func:`raise_if_interrupted`) where raising is clean. For a loop whose callee prints the traceback of
    any exception raised inside it: emcee's likelihood wrapper printed a KeyboardInterrupt's before the
    CLI's "interrupted" line. On leaving, a mark set meanwhile raises."""
    DEFERRING.set()
    try:
        yield
    finally:
        DEFERRING.clear()
    raise_if_interrupted()


def raise_if_interrupted() -> None:
    if INTERRUPTED.is_set():
        raise KeyboardInterrupt
STALE_AGE_S = 86400.0
KILL_POINTS = ("after_temp_created", "after_summary_written", "after_old_moved_aside",
               "after_new_renamed_in", "before_old_deleted")
# files the releases before the marker wrote into a run folder (see is_legacy_run)
LEGACY_FILES = frozenset({"summary.json", "metrics.json", "params.yaml", "config.resolved.yaml",
                          "report.html", "manifest.json", "extended.yaml"})
# location prefixes and filesystem types that are not a place for a run folder
PSEUDO_PREFIXES = (Path("/proc"), Path("/sys"), Path("/dev"))
PSEUDO_FSTYPES = frozenset({"proc", "sysfs", "devtmpfs", "devpts", "cgroup", "cgroup2", "securityfs",
                            "debugfs", "tracefs", "configfs", "fusectl", "pstore", "bpf", "mqueue",
                            "binfmt_misc", "autofs", "efivarfs", "hugetlbfs", "rpc_pipefs", "nsfs"})
# temp name suffix: ".tmp-" + pid (<= 10 digits) + "-" + 8 hex, plus the leading dot and joining dot
_SUFFIX_BYTES = 1 + 1 + len("tmp-") + 10 + 1 + 8
_SIDE = re.compile(r"^\.(?P<name>.+)\.(?P<kind>tmp|old)-(?P<pid>[0-9]{1,10})-(?P<rand>[0-9a-f]{8})$")


def kill_point(point: str) -> None:
    """Test hook: SIGKILL this process at ``point`` when ``SYSID_TEST_KILL_AT`` names it."""
    if os.environ.get("SYSID_TEST_KILL_AT") == point:
        os.kill(os.getpid(), signal.SIGKILL)


def _err(target: Path | str, what: str) -> InputError:
    return InputError(f"{target}: {what}", key="--out")


# ---------------------------------------------------------------- recognising run folders


def read_marker(folder: Path) -> dict | None:
    """The parsed marker of ``folder`` if it is this tool's, else None (never raises on bad content)."""
    m = Path(folder) / MARKER
    try:
        if not stat.S_ISREG(os.lstat(m).st_mode):
            return None
        data = json.loads(m.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("tool") != TOOL or not isinstance(data.get("files"), dict):
        return None
    return data


def is_legacy_run(folder: Path) -> bool:
    """A run folder written before the marker existed: only regular files named as the old
    ``write_run`` named them, with ``summary.json`` of schema ``sysid-summary/*`` and ``manifest.json``
    whose ``versions`` name ``sysid-pipeline``."""
    folder = Path(folder)
    try:
        entries = list(os.scandir(folder))
        if not entries or any(not e.is_file(follow_symlinks=False) or e.name not in LEGACY_FILES
                              for e in entries):
            return False
        summary = json.loads((folder / "summary.json").read_text(encoding="utf-8"))
        manifest = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return (isinstance(summary, dict) and str(summary.get("schema", "")).startswith("sysid-summary/")
            and isinstance(manifest, dict) and isinstance(manifest.get("versions"), dict)
            and TOOL in manifest["versions"])


def _listed_files_ok(folder: Path, files: dict, content: bool = False) -> bool:
    """Every listed file is a regular file of its listed size, and with ``content`` also of its
    listed sha256 (format 2 entries ``{"size", "sha256"}``; a format-1 entry is the size alone)."""
    for rel, entry in files.items():
        if not isinstance(rel, str) or Path(rel).is_absolute() or ".." in Path(rel).parts:
            return False
        size = entry.get("size") if isinstance(entry, dict) else entry
        try:
            st = os.lstat(folder / rel)
        except OSError:
            return False
        if not stat.S_ISREG(st.st_mode) or st.st_size != size:
            return False
        if content and isinstance(entry, dict):
            try:
                if file_sha256(folder / rel) != entry.get("sha256"):
                    return False
            except OSError:
                return False
    return True


def is_complete_run(folder: Path) -> bool:
    """True when ``folder`` is a real folder (not a symlink) holding a complete run of this tool:
    a valid marker whose every listed file exists with its listed size, or a legacy run folder."""
    folder = Path(folder)
    try:
        if not stat.S_ISDIR(os.lstat(folder).st_mode):
            return False
    except OSError:
        return False
    marker = read_marker(folder)
    if marker is None:
        return is_legacy_run(folder)
    return _listed_files_ok(folder, marker["files"])


def is_replaceable_run(folder: Path) -> bool:
    """A complete run folder holding nothing else: every file below it is listed in the marker, with
    its listed content (or it is a legacy run folder). A run folder to which the user added a file, or
    in which a file was edited, is not replaceable."""
    folder = Path(folder)
    if not is_complete_run(folder):
        return False
    marker = read_marker(folder)
    if marker is None:
        return True  # legacy: is_legacy_run already allows only the old file names
    if not _listed_files_ok(folder, marker["files"], content=True):
        return False
    allowed = set(marker["files"]) | {MARKER}
    for dirpath, dirnames, filenames in os.walk(folder):
        for fn in filenames:   # os.walk lists symlinks to folders as dirnames: check those too
            if str((Path(dirpath) / fn).relative_to(folder)) not in allowed:
                return False
        for dn in dirnames:
            if (Path(dirpath) / dn).is_symlink():
                return False
    return True


def _changes(d: Path, listed: dict, *, added: bool) -> list[tuple[str, list[str]]]:
    """The files of run folder ``d`` edited or missing against its marker's list (and, with ``added``,
    the files below it that the list does not hold), as (word, sorted names) pairs that are not empty."""
    edited = sorted(r for r, entry in listed.items() if isinstance(entry, dict) and (d / r).is_file()
                    and entry.get("sha256") != file_sha256(d / r))
    missing = sorted(r for r in listed if not (d / r).is_file())
    extra = sorted(rel for dirpath, _, filenames in os.walk(d) for fn in filenames
                   if (rel := str((Path(dirpath) / fn).relative_to(d))) != MARKER and rel not in listed) if added else []
    return [(w, v) for w, v in (("added", extra), ("edited", edited), ("missing", missing)) if v]


def _words(changes: list[tuple[str, list[str]]]) -> str:
    return "; ".join(f"{w}: {', '.join(v[:5])}" for w, v in changes)


def why_not_replaceable(d: Path) -> str:
    """What makes the existing ``d`` not a replaceable run folder, in words: the files added, edited or
    missing against its marker (for messages only; the decision is :func:`is_replaceable_run`'s)."""
    if d.is_symlink() or not d.is_dir():
        return "is not a folder" if not d.is_symlink() else "is a symlink"
    marker = read_marker(d)
    if marker is None:
        return f"is not a run folder of this tool (no valid {MARKER} marker)"
    changes = _changes(d, marker["files"], added=True)
    return "holds files this tool did not write" + (f" ({_words(changes)})" if changes else "")


def why_not_as_written(d: Path) -> str | None:
    """None when the run folder's files are as this tool wrote them (or it has no marker: a legacy
    folder, read as it is), else what was changed: the marker's files edited or missing. Files added
    beside them (a user's notes) do not change what the run says and are not counted."""
    marker = read_marker(d)
    changes = _changes(d, marker["files"], added=False) if marker is not None else []
    return f"was changed after the run ({_words(changes)})" if changes else None


def iter_run_folders(root: Path, skipped: list[Path] | None = None) -> Iterator[Path]:
    """Every complete run folder at or below ``root``, in sorted order. Hidden entries (temp and
    moved-aside folders of this tool among them) are never entered, symlinks never followed, and a
    run folder's own subfolders are not searched. ``skipped`` collects the folders that carry this
    tool's marker but are no longer complete (a file edited, added or removed by hand)."""
    root = Path(root)
    if is_complete_run(root):
        yield root
        return
    if skipped is not None and os.path.isfile(root / MARKER):
        skipped.append(root)
        return
    try:
        entries = sorted(os.scandir(root), key=lambda e: e.name)
    except OSError:
        return
    for e in entries:
        if e.name.startswith(".") or not e.is_dir(follow_symlinks=False):
            continue
        yield from iter_run_folders(Path(e.path), skipped)


# ---------------------------------------------------------------- checking a target


def _is_within(path: Path, folder: Path) -> bool:
    """``path`` equals ``folder`` or lies below it (both absolute and resolved)."""
    return path == folder or folder in path.parents


def _mount_fstype(path: Path) -> str | None:
    """Filesystem type of the mount holding ``path`` (from /proc/self/mountinfo), None if unknown."""
    try:
        lines = Path("/proc/self/mountinfo").read_text().splitlines()
    except OSError:
        return None
    best, fstype = -1, None
    for ln in lines:
        left, _, right = ln.partition(" - ")
        fields = left.split()
        if len(fields) < 5 or not right:
            continue
        mnt = Path(fields[4].replace("\\040", " "))
        if _is_within(path, mnt) and len(mnt.parts) > best:
            best, fstype = len(mnt.parts), right.split()[0]
    return fstype


def resolve_target(target: Path) -> Path:
    """Absolute ``target`` with every symlink in its parents resolved; the last component is kept
    as given (so a symlink *at* the target is seen, not followed), except ``.``/``..``/empty."""
    target = Path(target)
    if target.name in ("", ".."):   # pathlib drops "." components; "", ".." name a folder, resolve it
        return Path(os.path.realpath(target))
    return Path(os.path.realpath(target.parent)) / target.name


def input_folders(inputs: list[Path]) -> list[Path]:
    """The folders of the given input files: the folder as named and the folder of the real file."""
    out: list[Path] = []
    for p in inputs:
        p = Path(p)
        for f in (Path(os.path.realpath(p.parent)), Path(os.path.realpath(p)).parent):
            if f not in out:
                out.append(f)
    return out


def _check_lengths(target: Path, shown: str) -> None:
    probe = next((p for p in [target.parent, *target.parent.parents] if os.path.isdir(p)), Path("/"))
    try:
        name_max = os.pathconf(probe, "PC_NAME_MAX")
        path_max = os.pathconf(probe, "PC_PATH_MAX")
    except (OSError, ValueError):
        name_max, path_max = 255, 4096
    for part in target.parts[1:]:
        n = len(os.fsencode(part))
        limit = name_max - _SUFFIX_BYTES if part == target.name else name_max
        if n > limit:
            why = (f"NAME_MAX {name_max} less the temporary-folder suffix" if part == target.name
                   else f"NAME_MAX {name_max}")
            raise _err(shown, f"the name {part[:40]!r}... is {n} bytes; at most {limit} are possible here "
                       f"({why}); choose a shorter name")
    # the longest path the run writes: a file inside the temporary folder
    n = len(os.fsencode(str(target))) + _SUFFIX_BYTES + len("/config.resolved.yaml")
    if n >= path_max:
        raise _err(shown, f"the path is {n} bytes with the files inside; at most {path_max - 1} (PATH_MAX) "
                   "are possible; choose a shorter path")


# folders whose contents belong to a version-control tool: a run folder written there becomes part of its
# internals (an independent probe wrote one into .git/ of a checkout)
VCS_FOLDERS = (".git", ".hg", ".svn")


def _check_location(target: Path, shown: str) -> None:
    vcs = next((part for part in target.parts[:-1] if part in VCS_FOLDERS), None)
    if vcs is not None or target.name in VCS_FOLDERS:
        raise _err(shown, f"is inside a {vcs or target.name} folder, which belongs to version control; "
                   "expected a folder outside it (e.g. reports/NAME)")
    for pre in PSEUDO_PREFIXES:
        if _is_within(target, pre):
            raise _err(shown, f"is under {pre}, not a normal writable filesystem; expected a folder on disk")
    fst = _mount_fstype(target.parent)
    if fst in PSEUDO_FSTYPES:
        raise _err(shown, f"is on a {fst} filesystem, not a normal writable one; expected a folder on disk")


def _check_parent(target: Path, shown: str, *, default: bool) -> None:
    parent = target.parent
    try:
        st = os.stat(parent)
    except FileNotFoundError:
        if not default:
            raise _err(shown, f"the parent folder {parent} does not exist; create it first "
                       "(--out is the run folder itself)") from None
        # the default reports/ is created when the run is written: its nearest ancestor must do
        anc = next(p for p in parent.parents if os.path.lexists(p))
        if not os.path.isdir(anc) or not os.access(anc, os.W_OK | os.X_OK):
            raise _err(shown, f"cannot create the parent folder {parent}: {anc} is not a writable folder") from None
        return
    except NotADirectoryError:
        raise _err(shown, f"a component of the parent {parent} is a file, not a folder") from None
    except OSError as exc:
        raise _err(shown, f"cannot reach the parent folder {parent}: {exc.strerror}") from None
    if not stat.S_ISDIR(st.st_mode):
        raise _err(shown, f"the parent {parent} is not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise _err(shown, f"the parent folder {parent} is not writable")
    # a real probe (read-only mounts, quotas, odd filesystems): create and remove one temp name
    probe = parent / _side_name(target.name, "tmp")
    try:
        os.mkdir(probe, 0o700)
        os.rmdir(probe)
    except OSError as exc:
        raise _err(shown, f"cannot create a folder in {parent}: {exc.strerror}") from None


def check_new_path(path: Path | str, *, key: str, folder: bool) -> Path:
    """A file or folder a command creates itself (a gradebook, a batch root, an assignment folder),
    checked before any work: not on /proc, /sys, /dev or another pseudo filesystem; an existing one is
    of the right kind (a folder when ``folder``, else a regular file; never a symlink); its parent is a
    folder (created when missing, if its nearest existing ancestor is a writable folder). Returns it
    resolved; raises :class:`InputError` naming ``key``. Whether an existing one may be replaced is
    the caller's decision."""
    shown = str(path)
    if not shown or "\0" in shown:
        raise InputError(f"{shown!r} is not a usable path", key=key)
    try:
        resolved = resolve_target(Path(path))
        _check_location(resolved, shown)
        _check_parent(resolved, shown, default=True)
        st = os.lstat(resolved)
    except FileNotFoundError:
        return resolved
    except InputError as exc:       # the run-folder checks name --out: name this command's key
        raise InputError(exc.message, key=key) from None
    except OSError as exc:
        raise InputError(f"{shown}: cannot use this path: {exc.strerror}", key=key) from None
    if stat.S_ISLNK(st.st_mode):
        raise InputError(f"{shown}: is a symlink; expected a {'folder' if folder else 'file'} path, not a link",
                         key=key)
    if folder and not stat.S_ISDIR(st.st_mode):
        raise InputError(f"{shown}: exists and is not a folder", key=key)
    if not folder and not stat.S_ISREG(st.st_mode):
        raise InputError(f"{shown}: exists and is not a regular file", key=key)
    return resolved


def _check_existing(target: Path, shown: str) -> None:
    try:
        st = os.lstat(target)
    except FileNotFoundError:
        return
    except OSError as exc:
        raise _err(shown, f"cannot inspect it: {exc.strerror}") from None
    expected = "expected a new or empty folder, or an earlier run folder of this tool"
    if stat.S_ISLNK(st.st_mode):
        raise _err(shown, f"is a symlink (to {os.readlink(target)}); {expected}, not a link")
    if not stat.S_ISDIR(st.st_mode):
        kind = "a file" if stat.S_ISREG(st.st_mode) else "not a folder"
        raise _err(shown, f"exists and is {kind}; {expected}")
    try:
        empty = not any(os.scandir(target))
    except OSError as exc:
        raise _err(shown, f"cannot list the folder: {exc.strerror}") from None
    if not empty and not is_replaceable_run(target):
        raise _err(shown, f"exists and holds files this tool did not write (not exactly the files of a "
                   f"complete run listed in its {MARKER} marker); {expected}; nothing was changed")


def check_target(target: Path | str, *, inputs: list[Path], default: bool) -> Path:
    """Check that ``target`` may be written as a run folder and return it resolved (parents' symlinks
    resolved, absolute). ``inputs`` are the files the run reads (config, data); ``default`` is True for
    the default ``reports/<run-id>``, whose parent is then created when missing.

    Raises :class:`InputError` (key ``--out``) when the target is a file, a symlink, or a non-empty
    folder that is not a complete run folder of this tool; when it is the current folder or one of its
    ancestors, or equal to or an ancestor of the folder of an input; when its parent is missing (a
    user-given ``--out``), not a folder or not writable; when a name or the path is too long
    (``NAME_MAX`` less the temp-folder suffix, ``PATH_MAX``); or when it lies on /proc, /sys, /dev or
    another pseudo filesystem.
    """
    shown = str(target)
    if not shown or "\0" in shown:
        raise _err(repr(shown), "is not a usable path; expected a folder name")
    try:
        resolved = resolve_target(Path(target))
    except OSError as exc:   # e.g. a symlink loop or an over-long name in the parents
        raise _err(shown, f"cannot resolve the path: {exc.strerror}") from None
    _check_lengths(resolved, shown)
    _check_location(resolved, shown)
    try:
        cwd = Path(os.path.realpath(os.getcwd()))
    except OSError:          # the current folder was deleted: nothing to protect there
        cwd = Path("/nonexistent-cwd")
    if _is_within(cwd, resolved):
        what = "the current folder" if cwd == resolved else f"an ancestor of the current folder {cwd}"
        raise _err(shown, f"is {what}; expected a new folder for this run (e.g. reports/NAME)")
    for inp, folder in ((i, f) for i in inputs for f in input_folders([i])):
        if _is_within(folder, resolved):
            raise _err(shown, f"contains the input {inp} (the folder of an input or an ancestor of it); "
                       "expected a separate folder for this run")
    _check_parent(resolved, shown, default=default)
    # under a shared lock: between a concurrent publish's two renames the target is briefly absent,
    # and a check that had just seen it would call it foreign
    with _publish_lock(resolved, shared=True):
        _check_existing(resolved, shown)
    return resolved


# ---------------------------------------------------------------- writing and publishing


def _side_name(name: str, kind: str) -> str:
    return f".{name}.{kind}-{os.getpid()}-{secrets.token_hex(4)}"


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OverflowError:
        return False
    return True


def clean_stale(parent: Path, *, now: float | None = None) -> list[Path]:
    """Remove the temp/old folders of dead runs in ``parent``: only real folders (not symlinks) named
    ``.<name>.tmp-<pid>-<hex8>`` or ``.<name>.old-<pid>-<hex8>`` whose pid is not alive or whose
    modification time is more than a day ago, and that this tool made: a temp folder holding the token
    ``.sysid-tmp`` (or a finalized one, with its marker) or nothing at all, a moved-aside folder that is
    a run of this tool. Returns what was removed; errors are ignored."""
    now = time.time() if now is None else now
    removed = []
    try:
        entries = list(os.scandir(parent))
    except OSError:
        return removed
    for e in entries:
        m = _SIDE.match(e.name)
        if not m:
            continue
        try:
            st = e.stat(follow_symlinks=False)
        except OSError:
            continue
        if not stat.S_ISDIR(st.st_mode):
            continue
        if _pid_alive(int(m["pid"])) and now - st.st_mtime < STALE_AGE_S:
            continue
        if not _made_here(Path(e.path), m["kind"]):
            continue
        shutil.rmtree(e.path, ignore_errors=True)
        removed.append(Path(e.path))
    return removed


def _made_here(folder: Path, kind: str) -> bool:
    """Was ``folder`` (named as this tool's temp or moved-aside folder) made by this tool?"""
    try:
        entries = [e.name for e in os.scandir(folder)]
    except OSError:
        return False
    if kind == "tmp" and (not entries or TMP_TOKEN in entries):
        return True            # killed between mkdir and the token, or while writing
    return read_marker(folder) is not None or is_legacy_run(folder)


def make_temp(target: Path) -> Path:
    """Create the hidden, unique temp folder for ``target`` beside it (mode ``0o777 & ~umask``),
    after removing stale ones of dead runs in the same parent."""
    clean_stale(target.parent)
    for _ in range(100):
        tmp = target.parent / _side_name(target.name, "tmp")
        try:
            os.mkdir(tmp, 0o777)
        except FileExistsError:
            continue
        except OSError as exc:
            raise _err(target, f"cannot create a folder in {target.parent}: {exc.strerror}") from None
        (tmp / TMP_TOKEN).write_text(f"{TOOL} {os.getpid()}\n", encoding="utf-8")
        kill_point("after_temp_created")
        return tmp
    raise _err(target, f"cannot find a free temporary name in {target.parent}")


def _fsync_path(path: Path, *, directory: bool = False) -> None:
    flags = os.O_RDONLY | (os.O_DIRECTORY if directory else 0)
    try:
        fd = os.open(path, flags)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def finalize(tmp: Path, run_id: str) -> None:
    """Flush every file of ``tmp`` to disk and write the marker last (listing every file and its
    size and sha256), so ``tmp`` counts as complete only once everything else is there. The temp token
    goes first: from here the marker says whose folder it is."""
    with contextlib.suppress(FileNotFoundError):
        os.unlink(tmp / TMP_TOKEN)
    files: dict[str, dict] = {}
    for dirpath, dirnames, filenames in os.walk(tmp):
        dirnames.sort()
        for fn in sorted(filenames):
            p = Path(dirpath) / fn
            if p.is_symlink() or not p.is_file():
                continue
            _fsync_path(p)
            files[str(p.relative_to(tmp))] = {"size": p.stat().st_size, "sha256": file_sha256(p)}
        _fsync_path(Path(dirpath), directory=True)
    files.pop(MARKER, None)
    marker = {"tool": TOOL, "format": MARKER_FORMAT, "run_id": run_id, "files": files}
    with open(tmp / MARKER, "w", encoding="utf-8") as fh:
        fh.write(json.dumps(marker, indent=1, sort_keys=True) + "\n")
        fh.flush()
        os.fsync(fh.fileno())
    _fsync_path(tmp, directory=True)


@contextlib.contextmanager
def _publish_lock(target: Path, *, shared: bool = False) -> Iterator[None]:
    """flock serialising publishes into ``target.parent``: on the parent folder itself (no file left
    behind) or, where folders cannot be locked (some network filesystems), on ``.<name>.lock`` beside
    the target. ``shared``: the lock a check of the target takes (:func:`check_target`), so it never
    sees a publish half-way; best effort: it creates no lock file, and where nothing can be locked the
    check runs unlocked (:func:`publish` re-checks under its exclusive lock)."""
    lock_file = target.parent / f".{target.name}.lock"
    fd = -1
    for path, flags in ((target.parent, os.O_RDONLY | os.O_DIRECTORY),
                        (lock_file, os.O_RDONLY if shared else os.O_RDWR | os.O_CREAT)):
        try:
            fd = os.open(path, flags, 0o666)
            fcntl.flock(fd, fcntl.LOCK_SH if shared else fcntl.LOCK_EX)
            break
        except OSError as exc:
            if fd >= 0:
                os.close(fd)
            fd = -1
            if path == lock_file and not shared:
                raise _err(target, f"cannot lock {target.parent} for publishing: {exc.strerror}") from None
    try:
        yield
    finally:
        if fd >= 0:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)


def publish(tmp: Path, target: Path) -> Path:
    """Move the complete temp folder ``tmp`` to ``target`` atomically (see the module docstring).

    Under the lock the target is checked again (it may have changed during the analysis): absent or an
    empty folder takes one ``rename``; a complete run of this tool is renamed aside to a hidden name,
    the new run renamed in, then the old one deleted. Anything else raises :class:`InputError` and
    leaves the target untouched (``tmp`` is removed)."""
    target = Path(target)
    if INTERRUPTED.is_set():   # the KeyboardInterrupt itself may have been lost in a callback
        raise KeyboardInterrupt
    with _publish_lock(target):
        try:
            st = os.lstat(target)
        except FileNotFoundError:
            st = None
        fresh = st is None
        if not fresh and stat.S_ISDIR(st.st_mode) and not any(os.scandir(target)):
            fresh = True                 # an empty folder is replaced by the same single rename
        if fresh:
            try:
                os.rename(tmp, target)
            except OSError as exc:       # created or filled after the check: leave it alone
                if exc.errno not in (errno.ENOTEMPTY, errno.EEXIST, errno.ENOTDIR, errno.EISDIR):
                    raise
                raise _err(target, "something appeared at this path during the run; nothing was changed") from None
            kill_point("after_new_renamed_in")
            _fsync_path(target.parent, directory=True)
            return target
        if not is_replaceable_run(target):
            raise _err(target, "changed during the run and is no longer empty or an earlier run folder "
                       "of this tool; nothing was changed")
        old = target.parent / _side_name(target.name, "old")
        os.rename(target, old)
        kill_point("after_old_moved_aside")
        os.rename(tmp, target)
        kill_point("after_new_renamed_in")
        _fsync_path(target.parent, directory=True)
        kill_point("before_old_deleted")
        shutil.rmtree(old, ignore_errors=True)
    return target
