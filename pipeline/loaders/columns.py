"""Messages shared by the loaders: a missing or duplicated column, a non-numeric value (and a time
column that holds dates or text), too many rows. Each is a :class:`DataError` naming file and column."""

from __future__ import annotations

import warnings

import numpy as np
import pandas as pd

from ..errors import DataError

_BOOL = {"true": 1.0, "false": 0.0}


def missing(name: str, available: list[str], role: str, f: str, key: str | None) -> DataError:
    """Column ``name`` is not in the file: list what is (and a near miss that differs in spaces/case)."""
    near = [c for c in available if c.strip().lower() == name.strip().lower()]
    hint = f" (did you mean {near[0]!r}?)" if near else ""
    # one header cell holding the name between other separators: the file uses another delimiter
    if not near and len(available) == 1:
        cell = available[0]
        sep = next((s for s in (";", "\t", "|", ",", " ") if name in [p.strip() for p in cell.split(s)]), None)
        if sep is not None:
            hint = f" (the header reads as one column {cell!r}: set data.delimiter: {sep!r})"
    avail = ", ".join(repr(c) for c in available[:12]) + (", ..." if len(available) > 12 else "")
    return DataError(f"column {name!r} ({role}) not found{hint}; columns: {avail or '(none)'}", file=f, key=key)


def duplicated(name: str, positions: list[int], f: str, key: str | None) -> DataError:
    where = " and ".join(str(p + 1) for p in positions)
    return DataError(f"column {name!r} appears {len(positions)} times in the header (columns {where}); "
                     "rename one so the choice is not silent", file=f, key=key)


def too_many_rows(limit: int, f: str, key: str | None) -> DataError:
    return DataError(f"the file holds more than data.max_samples = {limit} rows; the diagnosis needs about "
                     "2.5 kB of memory and 0.2 ms a sample (2 000 000 rows: 4.9 GB, 7.5 min): cut the record, or "
                     "raise data.max_samples and decimate it (prefilter: decimate)", file=f, key=key)


def _looks_like_date(value: str) -> bool:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            pd.Timestamp(str(value).strip())
        return True
    except (ValueError, TypeError, OverflowError):
        return False


def non_numeric(name: str, value, row: int, is_time: bool, f: str, key: str | None) -> DataError:
    """The first value of column ``name`` that is not a number, at data row ``row`` (0-based)."""
    if is_time:
        what = "dates or clock times" if _looks_like_date(value) else "text"
        return DataError(f"time column {name!r} holds {what} ({value!r} at row {row}); give seconds "
                         "(e.g. since the first sample) or use data.sample_time", file=f, key=key)
    return DataError(f"column {name!r} has a non-numeric value {value!r} at row {row}", file=f, key=key)


def to_float(s: pd.Series, name: str, is_time: bool, f: str, key: str | None, decimal: str = ".") -> np.ndarray:
    """float64 values of a column read as text (NaN kept); the first non-numeric value is an error.
    A column of only true/false (any case) reads as 1/0."""
    if s.dtype.kind in "fiu":
        return s.to_numpy(dtype=np.float64)
    if s.dtype.kind == "b":
        return s.to_numpy(dtype=np.float64)
    if s.dtype.kind == "M" or isinstance(s.dtype, pd.DatetimeTZDtype):
        raise non_numeric(name, str(s.iloc[0]), 0, True, f, key) if is_time else \
            DataError(f"column {name!r} holds dates, not numbers", file=f, key=key)
    text = s.astype("string").str.strip()
    low = text.str.lower()
    present = text.notna().to_numpy()
    if present.any() and low[present].isin(list(_BOOL)).all():
        return low.map(_BOOL).to_numpy(dtype=np.float64, na_value=np.nan)
    conv = pd.to_numeric(text.str.replace(",", ".", regex=False) if decimal == "," else text, errors="coerce")
    bad = np.flatnonzero(conv.isna().to_numpy() & present)
    if len(bad):
        raise non_numeric(name, str(s.iloc[bad[0]]), int(bad[0]), is_time, f, key)
    return conv.to_numpy(dtype=np.float64, na_value=np.nan)
