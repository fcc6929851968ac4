"""Readers of data files into named float64 columns, one module per format.

:func:`read_columns` is the only entry point: it checks the file with ``os.stat`` before reading it
(:mod:`.files`: exists, a regular file, not empty, at most ``data.max_bytes``; text formats must not
look binary), then reads **only the needed columns**, bounded by ``data.max_samples`` rows:

========  ============================================================  =====================
format    what                                                          module
========  ============================================================  =====================
csv       delimited text with a header line (.csv, .txt)                :mod:`.text`
table     delimited text without header, names from data.columns (.dat)  :mod:`.text`
parquet   Apache Parquet (.parquet, .pq)                                :mod:`.parquet`
mat       MATLAB v5/v7 (.mat); samples along the longer dimension       :mod:`.mat`
========  ============================================================  =====================

Values come back as float64 with NaN where a value is missing; the record checks (pipeline.data)
report NaN, inf and length mismatches. Non-numeric values are reported here with their row.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import DataError
from .files import check_file, check_text
from .mat import read_mat
from .parquet import read_parquet
from .spec import DEFAULT_MAX_BYTES, DEFAULT_MAX_SAMPLES, SUFFIXES, ReadSpec
from .text import read_csv, read_table

__all__ = ["ReadSpec", "read_columns", "resolve_format", "DEFAULT_MAX_BYTES", "DEFAULT_MAX_SAMPLES"]

_READERS = {"csv": read_csv, "table": read_table, "parquet": read_parquet, "mat": read_mat}


def resolve_format(path: Path, fmt: str | None, *, key: str | None = None) -> str:
    """The configured format, else the one implied by the suffix."""
    fmt = fmt or SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        raise DataError(f"unknown data format {path.suffix!r}; expected .csv, .parquet, .mat or .dat "
                        "(or set data.format: csv | table | parquet | mat)", file=str(path), key=key)
    return fmt


def _check_options(path: Path, spec: ReadSpec, fmt: str, key: str) -> None:
    """Options that do not apply to the file's format are an error, not silently ignored."""
    given = {"columns": spec.columns is not None and fmt != "table",
             "delimiter": spec.delimiter is not None and fmt not in ("csv", "table"),
             "decimal": spec.decimal != "." and fmt not in ("csv", "table"),
             "comment": spec.comment is not None and fmt not in ("csv", "table"),
             "skip_rows": spec.skip_rows != 0 and fmt not in ("csv", "table")}
    for opt, bad in given.items():
        if bad:
            what = "headerless tables (data.format: table)" if opt == "columns" else "text formats (csv, table)"
            raise DataError(f"only for {what}; this file is read as {fmt}", file=str(path),
                            key=f"{key}.{opt}")


def read_columns(path: Path, spec: ReadSpec, needed: dict[str, str], *, time: str | None = None,
                 key: str | None = None) -> dict[str, np.ndarray]:
    """float64 arrays of the columns ``needed`` (name -> role, e.g. "input", for messages) of ``path``.

    ``time`` names the time column (a non-numeric value there gets the "give seconds" message);
    ``key`` is the config key of the record (e.g. ``data.validation``), added to every message."""
    path_key = f"{key or 'data'}.path"    # problems of the file as a whole name the key that chose it
    check_file(path, spec.max_bytes, key=path_key)
    fmt = resolve_format(path, spec.format, key=path_key)
    _check_options(path, spec, fmt, key or "data")
    if fmt in ("csv", "table"):
        check_text(path, fmt, key=path_key)
    spec = replace(spec, format=fmt)
    return _READERS[fmt](path, spec, needed, time, key)
