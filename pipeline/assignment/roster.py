"""The class roster: a CSV with columns ``id``, ``name`` and optionally ``email`` (other columns are
ignored). Ids must be unique and made of letters, digits, ``_ . -`` (they name folders and runs)."""

from __future__ import annotations

import csv
import io
import re
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError

ID_PATTERN = re.compile(r"^[A-Za-z0-9_.-]{1,40}$")


@dataclass(frozen=True)
class Student:
    id: str
    name: str
    email: str | None = None


def id_problem(sid: str) -> str | None:
    """What is wrong with ``sid`` as a student id, or None. One rule for the roster and the key:
    an id names the student's folders (``students/<id>``, ``submissions/<id>``, ``runs/<id>``), so
    ``..``, ``/`` and the like would make grading read and write outside those folders."""
    if not sid:
        return "empty id"
    if not ID_PATTERN.match(sid):
        return f"id {sid!r} may only use letters, digits, '_', '.', '-' (at most 40)"
    if sid in (".", ".."):
        return f"id {sid!r} is not a usable folder name"
    if sid.startswith("."):      # a hidden folder: file browsers and `sysid runs` do not list it
        return f"id {sid!r} starts with '.', which would make the student's folders hidden"
    return None


def load_roster(path: str | Path) -> list[Student]:
    """Read and check the roster. Raises InputError naming the file, the row and the column."""
    path = Path(path)
    f = str(path)
    if not path.is_file():
        raise InputError("roster not found", file=f)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", file=f) from None
    try:
        # the csv module's own line handling: a quoted name may hold a line break ("Ada<newline>Lovelace"),
        # which splitting the text into lines first turned into two rows and then "AdaLovelace"
        rows = list(csv.reader(io.StringIO(text, newline="")))
    except csv.Error as exc:
        raise InputError(f"not a valid CSV file ({exc})", file=f) from None
    rows = [r for r in rows if any(c.strip() for c in r)]
    if not rows:
        raise InputError("the roster is empty; expected a header line 'id,name[,email]' and one row per student",
                         file=f)
    header = [c.strip().lower() for c in rows[0]]
    for col in ("id", "name"):
        if col not in header:
            found = ", ".join(header)[:60] or "nothing"
            raise InputError(f"no column {col!r} in the header (found: {found}); expected 'id,name[,email]'",
                             file=f)
    for col in ("id", "name", "email"):
        if header.count(col) > 1:    # which one is meant cannot be guessed
            raise InputError(f"the header names the column {col!r} {header.count(col)} times; expected it once",
                             file=f)
    i_id, i_name = header.index("id"), header.index("name")
    i_mail = header.index("email") if "email" in header else None
    students: list[Student] = []
    seen: dict[str, int] = {}
    for line, r in enumerate(rows[1:], start=2):
        cell = (lambda i: r[i].strip() if i is not None and i < len(r) else "")
        sid, name = cell(i_id), " ".join(cell(i_name).split())   # a line break in a quoted name: a space
        problem = id_problem(sid)
        if problem:
            raise InputError(problem, file=f, key=f"row {line}: id")
        if sid.lower() in seen:  # folders of ids differing only in case collide on some file systems
            raise InputError(f"id {sid!r} appears twice (also on row {seen[sid.lower()]}; ids are compared "
                             "ignoring case)", file=f, key=f"row {line}: id")
        if not name:
            raise InputError("empty name", file=f, key=f"row {line}: name")
        seen[sid.lower()] = line
        students.append(Student(sid, name, cell(i_mail) or None))
    if not students:
        raise InputError("the roster has a header but no students", file=f)
    return students
