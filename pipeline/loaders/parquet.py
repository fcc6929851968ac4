"""Parquet (pyarrow): only the needed columns are read, after checking the row count from the file's
metadata against ``data.max_samples`` and the decoded size (rows x needed columns x 8 bytes) against
``data.max_bytes``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import DataError
from . import columns as msg
from .files import human_bytes
from .spec import ReadSpec


def read_parquet(path: Path, spec: ReadSpec, needed: dict[str, str], time: str | None,
                 key: str | None) -> dict[str, np.ndarray]:
    import pyarrow.parquet as pq
    f = str(path)
    try:
        pf = pq.ParquetFile(f)
        names = list(pf.schema_arrow.names)
        rows = pf.metadata.num_rows
    except Exception as exc:  # a broken file is bad input, not an internal error
        raise DataError(f"cannot read as parquet ({type(exc).__name__}: {exc})", file=f, key=key) from None
    for name, role in needed.items():
        if name not in names:
            raise msg.missing(name, [n for n in names if not n.startswith("__index_level")], role, f, key)
        pos = [j for j, n in enumerate(names) if n == name]
        if len(pos) > 1:
            raise msg.duplicated(name, pos, f, key)
    if rows > spec.max_samples:
        raise msg.too_many_rows(spec.max_samples, f, key)
    if rows * len(needed) * 8 > spec.max_bytes:
        raise DataError(f"{rows} rows x {len(needed)} columns decode to {human_bytes(rows * len(needed) * 8)}, "
                        f"more than data.max_bytes ({human_bytes(spec.max_bytes)})", file=f, key=key)
    if rows == 0:
        raise DataError("the file holds no data rows", file=f, key=key)
    try:
        table = pf.read(columns=list(needed))
    except Exception as exc:
        raise DataError(f"cannot read as parquet ({type(exc).__name__}: {exc})", file=f, key=key) from None
    out = {}
    for name in needed:
        s = table.column(name).to_pandas()
        out[name] = np.ascontiguousarray(msg.to_float(s, name, name == time, f, key), dtype=np.float64)
    return out
