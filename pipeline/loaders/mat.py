"""MATLAB v5/v6/v7 ``.mat`` files (``scipy.io``; v7.3 is HDF5 and refused with a hint).

Columns of a file (from :func:`scipy.io.whosmat`, before any data are read):

* a numeric vector (1 x N or N x 1, N > 1) is the column ``<var>``;
* a numeric matrix with both dimensions > 1 holds one channel per row or per column; **samples run
  along the longer dimension** (a 3 x 73 728 matrix is 3 channels of 73 728 samples, as is its
  transpose; a square matrix is read column-wise, MATLAB's convention); channel j (1-based) is the
  column ``<var>_<j>``;
* scalars, text, cells, structs, sparse and N-d arrays are not columns.

Only the variables behind the needed columns are loaded (``variable_names``), after checking their
declared size against ``data.max_samples`` (the longer dimension) and ``data.max_bytes`` (decoded
bytes: a compressed variable can be far larger than the file).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import DataError
from . import columns as msg
from .files import human_bytes
from .spec import ReadSpec

_ITEMSIZE = {"double": 8, "single": 4, "int8": 1, "uint8": 1, "int16": 2, "uint16": 2, "int32": 4,
             "uint32": 4, "int64": 8, "uint64": 8, "logical": 1}


def catalogue(info: list[tuple[str, tuple, str]]) -> dict[str, tuple[str, int | None, int]]:
    """Column name -> (variable, channel index or None for a vector, axis along which samples run)."""
    cols: dict[str, tuple[str, int | None, int]] = {}
    for var, shape, cls in info:
        if cls not in _ITEMSIZE or len(shape) != 2 or min(shape) < 1 or max(shape) < 2:
            continue
        r, c = shape
        if r == 1 or c == 1:
            cols[var] = (var, None, 0 if c == 1 else 1)
        else:
            axis = 0 if r >= c else 1          # samples along the longer dimension
            for j in range(c if axis == 0 else r):
                cols[f"{var}_{j + 1}"] = (var, j, axis)
    return cols


def read_mat(path: Path, spec: ReadSpec, needed: dict[str, str], time: str | None,
             key: str | None) -> dict[str, np.ndarray]:
    import scipy.io
    f = str(path)
    try:
        info = scipy.io.whosmat(f)
    except NotImplementedError:
        raise DataError("MATLAB v7.3 (HDF5) files are not supported; save with -v7 or -v6", file=f, key=key) from None
    except Exception as exc:  # a broken file is bad input, not an internal error
        raise DataError(f"cannot read as mat ({type(exc).__name__}: {exc})", file=f, key=key) from None
    shapes = {var: (shape, cls) for var, shape, cls in info}
    cols = catalogue(info)
    for name, role in needed.items():
        if name not in cols:
            if name in shapes:
                shape, cls = shapes[name]
                raise DataError(f"variable {name!r} is a {'x'.join(map(str, shape))} {cls} array, not a signal "
                                "(a numeric vector, or a matrix of channels named <var>_<j>)", file=f, key=key)
            raise msg.missing(name, list(cols), role, f, key)
    variables = sorted({cols[name][0] for name in needed})
    for var in variables:
        shape, cls = shapes[var]
        n_bytes = int(np.prod(shape)) * _ITEMSIZE[cls]
        if max(shape) > spec.max_samples:
            raise DataError(f"variable {var!r} holds {max(shape)} samples, more than data.max_samples = "
                            f"{spec.max_samples}", file=f, key=key)
        if n_bytes > spec.max_bytes:
            raise DataError(f"variable {var!r} decodes to {human_bytes(n_bytes)}, more than data.max_bytes "
                            f"({human_bytes(spec.max_bytes)})", file=f, key=key)
    try:
        mat = scipy.io.loadmat(f, variable_names=variables, squeeze_me=False)
    except Exception as exc:
        raise DataError(f"cannot read as mat ({type(exc).__name__}: {exc})", file=f, key=key) from None
    out = {}
    for name in needed:
        var, j, axis = cols[name]
        v = np.asarray(mat[var])
        if v.dtype.kind not in "fiub":
            raise DataError(f"variable {var!r} holds {v.dtype} values, not real numbers", file=f, key=key)
        v = v.reshape(-1) if j is None else (v[:, j] if axis == 0 else v[j, :])
        out[name] = np.ascontiguousarray(v, dtype=np.float64)
    return out
