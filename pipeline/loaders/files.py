"""Checks on a data file before any byte of it is parsed: it exists, is a regular file (not a directory,
a FIFO or a device), is not empty, is not larger than ``data.max_bytes``, and, when text is expected,
does not look binary. Only ``os.stat`` and the first :data:`SNIFF_BYTES` bytes are used."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from ..errors import DataError

SNIFF_BYTES = 8192

# leading bytes of formats that are often handed over as "the CSV" (first match wins)
MAGIC: tuple[tuple[bytes, str], ...] = (
    (b"PAR1", "a Parquet file (set data.format: parquet)"),
    (b"MATLAB 5.0 MAT-file", "a MATLAB v5 .mat file (set data.format: mat)"),
    (b"MATLAB 7.3 MAT-file", "a MATLAB v7.3 .mat file (HDF5; save it with -v7 instead)"),
    (b"\x89HDF\r\n\x1a\n", "an HDF5 file"),
    (b"PK\x03\x04", "a ZIP archive (an .xlsx workbook?); export the sheet as CSV"),
    (b"\x1f\x8b", "a gzip archive; decompress it first"),
    (b"\xff\xfe", "UTF-16 text; save it as UTF-8"),
    (b"\xfe\xff", "UTF-16 text; save it as UTF-8"),
)


def human_bytes(n: int) -> str:
    """``n`` bytes in binary units (KiB, MiB, GiB), three significant digits."""
    for unit, size in (("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n} bytes"


def check_file(path: Path, max_bytes: int, *, key: str | None = None) -> int:
    """Size in bytes of the regular, non-empty data file ``path``; :class:`DataError` otherwise."""
    f = str(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise DataError("data file not found (data.path is relative to the config's folder)",
                        file=f, key=key) from None
    except OSError as exc:
        raise DataError(f"cannot open the data file ({exc.strerror or exc})", file=f, key=key) from None
    if stat.S_ISDIR(st.st_mode):
        raise DataError("is a directory, not a data file; give the path of the file inside it", file=f, key=key)
    if not stat.S_ISREG(st.st_mode):
        raise DataError("is not a regular file (a FIFO, socket or device?); give a data file", file=f, key=key)
    if st.st_size == 0:
        raise DataError("the data file is empty (0 bytes)", file=f, key=key)
    if st.st_size > max_bytes:
        raise DataError(f"the data file holds {human_bytes(st.st_size)}, more than data.max_bytes "
                        f"({human_bytes(max_bytes)}); raise data.max_bytes if this is intended", file=f, key=key)
    return st.st_size


def head(path: Path, n: int = SNIFF_BYTES) -> bytes:
    with open(path, "rb") as fh:
        return fh.read(n)


def check_text(path: Path, fmt: str, *, key: str | None = None) -> None:
    """A text format (csv, table) was asked for: refuse known binary formats and NUL bytes."""
    h = head(path)
    for magic, what in MAGIC:
        if h.startswith(magic):
            raise DataError(f"read as {fmt} text, but this is {what}", file=str(path), key=key)
    if b"\x00" in h:
        raise DataError(f"read as {fmt} text, but the file is binary (it holds NUL bytes in its first "
                        f"{len(h)} bytes)", file=str(path), key=key)
