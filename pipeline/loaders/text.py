"""Delimited text: ``csv`` (a header line naming the columns) and ``table`` (no header; the names come
from ``data.columns``, e.g. the DaISy ``.dat`` files).

Both: ``skip_rows`` lines are skipped first, then blank lines and lines starting with the comment
character; LF, CRLF and CR line endings; UTF-8 (a BOM is ignored); ``decimal`` "." or ",". Only the
needed columns are converted, to float64 (pandas' C parser, ``usecols`` for csv), and at most
``max_samples + 1`` rows are parsed, so memory stays near 8 bytes per needed value.

* csv: the header is read by :mod:`csv` (not pandas, which renames a duplicate ``x`` to ``x.1``
  silently); a needed name that appears twice is an error; columns are then selected by position.
* table: the first data line must hold exactly ``len(columns)`` fields (a trailing delimiter at the
  end of each line, as in DaISy's tab-separated files, is not a field); a later line with more fields
  is an error, one with fewer gives NaN in the missing columns, reported by the record checks.
"""

from __future__ import annotations

import csv
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import DataError
from . import columns as msg
from .spec import ReadSpec

MAX_LINE = 1 << 20   # characters of the header / first data line (a file without line breaks is no table)


def _first_lines(path: Path, spec: ReadSpec, f: str, key: str | None) -> tuple[int, str]:
    """(physical line index, text) of the first line after ``skip_rows`` that is neither blank nor a
    comment: the header of a csv, the first data line of a table."""
    try:
        with open(path, encoding="utf-8-sig", newline=None) as fh:
            i = 0
            while line := fh.readline(MAX_LINE + 1):
                if len(line) > MAX_LINE:
                    raise DataError(f"line {i + 1} is longer than {MAX_LINE} characters; is this delimited text "
                                    "with line breaks?", file=f, key=key)
                s = line.strip()
                if i >= spec.skip_rows and s and not (spec.comment and s.startswith(spec.comment)):
                    return i, line.rstrip("\r\n")
                i += 1
    except UnicodeDecodeError as exc:
        raise DataError(f"not UTF-8 text (byte 0x{exc.object[exc.start]:02x} is not valid UTF-8); save the "
                        "file as UTF-8", file=f, key=key) from None
    where = f" after data.skip_rows = {spec.skip_rows} lines" if spec.skip_rows else ""
    raise DataError(f"no data lines{where} (only blank or comment lines)", file=f, key=key)


def _fields(line: str, delimiter: str | None) -> list[str]:
    if delimiter is None:
        return line.split()
    parts = line.split(delimiter)
    return parts[:-1] if len(parts) > 1 and parts[-1].strip() == "" else parts


def _parse(path: Path, f: str, key: str | None, spec: ReadSpec, dtypes, **kw) -> pd.DataFrame:
    try:
        return pd.read_csv(path, header=None, comment=spec.comment, decimal=spec.decimal, encoding="utf-8",
                           nrows=spec.max_samples + 1, skip_blank_lines=True, engine="c", dtype=dtypes,
                           **kw)
    except pd.errors.EmptyDataError:
        return pd.DataFrame()
    except pd.errors.ParserError as exc:
        detail = str(exc).replace("Error tokenizing data. C error: ", "").strip()
        raise DataError(f"cannot read as {spec.format}: {detail}", file=f, key=key) from None
    except UnicodeDecodeError:
        raise DataError("not UTF-8 text; save the file as UTF-8", file=f, key=key) from None


def _convert(path: Path, f: str, key: str | None, spec: ReadSpec, cols: dict[str, object], time: str | None,
             **kw) -> dict[str, np.ndarray]:
    """Parse the columns ``cols`` (name -> pandas column label) as float64; on a non-numeric value,
    parse them again as text to say which value in which row."""
    labels = list(cols.values())
    try:
        df = _parse(path, f, key, spec, {lab: np.float64 for lab in labels}, **kw)
    except (ValueError, TypeError):
        df = _parse(path, f, key, spec, {lab: "string" for lab in labels}, **kw)
        for name, lab in cols.items():
            msg.to_float(df[lab], name, name == time, f, key, spec.decimal)
        raise DataError(f"cannot read as {spec.format}: a value is not a number", file=f, key=key) from None
    if len(df) > spec.max_samples:
        raise msg.too_many_rows(spec.max_samples, f, key)
    if len(df) == 0:
        raise DataError("the file holds no data rows" + (" after its header" if spec.format == "csv" else ""),
                        file=f, key=key)
    return {name: np.ascontiguousarray(df[lab].to_numpy(dtype=np.float64)) for name, lab in cols.items()}


def read_csv(path: Path, spec: ReadSpec, needed: dict[str, str], time: str | None,
             key: str | None) -> dict[str, np.ndarray]:
    """Columns ``needed`` (name -> role, for messages) of a csv file with a header line."""
    f = str(path)
    delim = spec.delimiter or ","
    if spec.decimal == delim:
        raise DataError(f"data.decimal {spec.decimal!r} equals the delimiter; set data.delimiter (e.g. ';')",
                        file=f, key=key)
    line_no, header_line = _first_lines(path, spec, f, key)
    header = next(csv.reader([header_line], delimiter=delim))
    positions: dict[str, list[int]] = {}
    for j, name in enumerate(header):
        positions.setdefault(name, []).append(j)
    for name, role in needed.items():
        if name not in positions:
            raise msg.missing(name, [h for h in header if h != ""], role, f, key)
        if len(positions[name]) > 1:
            raise msg.duplicated(name, positions[name], f, key)
    cols = {name: positions[name][0] for name in needed}
    # every row is read against the header's fields (pandas would take their number from the first
    # data row: a short first row failed inside pandas); a longer row is a parser error naming its line
    # (with ``usecols`` pandas drops a row's extra fields without a word, so every column is read)
    return _convert(path, f, key, spec, cols, time, sep=delim, skiprows=line_no + 1,
                    names=list(range(len(header))), index_col=False)


def read_table(path: Path, spec: ReadSpec, needed: dict[str, str], time: str | None,
               key: str | None) -> dict[str, np.ndarray]:
    """Columns ``needed`` of headerless delimited text whose columns are named by ``spec.columns``."""
    f = str(path)
    spec = replace(spec, comment=spec.comment or "#")
    if not spec.columns:
        raise DataError("data.format table needs data.columns: the name of every column, in file order",
                        file=f, key=key)
    if spec.decimal == spec.delimiter:
        raise DataError(f"data.decimal {spec.decimal!r} equals the delimiter; set data.delimiter",
                        file=f, key=key)
    names = list(spec.columns)
    line_no, first = _first_lines(path, spec, f, key)
    fields = _fields(first, spec.delimiter)
    if len(fields) != len(names):
        raise DataError(f"data.columns names {len(names)} columns ({', '.join(names)}) but the first data line "
                        f"(line {line_no + 1}) holds {len(fields)} fields: {first.strip()[:80]!r}", file=f, key=key)
    for name, role in needed.items():
        if name not in names:
            raise msg.missing(name, names, role, f, key)
    sep = r"\s+" if spec.delimiter is None else spec.delimiter
    return _convert(path, f, key, spec, {name: name for name in needed}, time, sep=sep, skiprows=line_no,
                    names=names, index_col=False)
