"""Records: loading (CSV, Parquet, MATLAB v5 .mat), validation, fingerprint, split.

Policies (each explicit; violations are :class:`DataError` naming file and column):
* missing column, non-numeric values, NaN/inf: error with the first offending row;
* time not strictly increasing: error with the first offending row;
* sampling intervals deviating from the median by more than ``data.max_jitter`` (relative): error that
  says by how much; smaller jitter is accepted, logged, and the median interval is used;
* fewer than ``data.min_samples`` samples, or a constant input: error.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .config import LoadedConfig
from .errors import DataError


@dataclass
class Record:
    """One measured record, columns renamed to the model's names."""

    t: np.ndarray                       # (N,) seconds, uniform
    dt: float
    inputs: dict[str, np.ndarray]       # model input name -> (N,)
    outputs: dict[str, np.ndarray]      # state / declared output name -> (N,)
    sha256: str
    path: str
    log: list[str] = field(default_factory=list)
    means: dict[str, float] = field(default_factory=dict)  # removed means (remove_mean)

    @property
    def n(self) -> int:
        return len(self.t)

    def u_matrix(self, names: list[str]) -> np.ndarray:
        if not names:
            return np.zeros((self.n, 1))
        return np.column_stack([self.inputs[k] for k in names])


@dataclass(frozen=True)
class Split:
    est: tuple[int, int]   # [start, stop) sample indices used for fitting
    val: tuple[int, int]   # [start, stop) never used for fitting

    def est_slice(self) -> slice:
        return slice(*self.est)

    def val_slice(self) -> slice:
        return slice(*self.val)


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _read_table(path: Path, fmt: str | None) -> dict[str, np.ndarray]:
    fmt = fmt or {".csv": "csv", ".txt": "csv", ".parquet": "parquet", ".pq": "parquet",
                  ".mat": "mat"}.get(path.suffix.lower())
    f = str(path)
    if fmt is None:
        raise DataError(f"unknown data format {path.suffix!r}; expected .csv, .parquet or .mat "
                        "(or set data.format)", file=f)
    try:
        if fmt == "mat":
            import scipy.io
            try:
                mat = scipy.io.loadmat(f, squeeze_me=False)
            except NotImplementedError:
                raise DataError("MATLAB v7.3 (HDF5) files are not supported; save with -v7 or -v6",
                                file=f) from None
            cols = {}
            for k, v in mat.items():
                if k.startswith("__") or not isinstance(v, np.ndarray) or v.dtype.kind not in "fiu":
                    continue
                if v.ndim == 2 and 1 in v.shape and v.size > 1:
                    cols[k] = v.ravel().astype(float)
                elif v.ndim == 2 and v.shape[1] > 1 and v.shape[0] > 1:
                    for j in range(v.shape[1]):
                        cols[f"{k}_{j + 1}"] = v[:, j].astype(float)
            return cols
        import pandas as pd
        if fmt == "csv":
            df = pd.read_csv(f)
        else:
            df = pd.read_parquet(f)
    except DataError:
        raise
    except Exception as exc:  # a broken file is bad input, not an internal error
        raise DataError(f"cannot read as {fmt} ({type(exc).__name__}: {exc})", file=f) from None
    df = df.loc[:, [c for c in df.columns if not (str(c).startswith("Unnamed") and df[c].isna().all())]]
    out = {}
    for c in df.columns:
        s = df[c]
        if s.dtype.kind not in "fiub":
            conv = pd.to_numeric(s, errors="coerce")
            bad = np.flatnonzero(conv.isna().to_numpy() & s.notna().to_numpy())
            if len(bad):
                out[str(c)] = ("nonnumeric", int(bad[0]), s.iloc[bad[0]])
                continue
            s = conv
        out[str(c)] = s.to_numpy(dtype=float)
    return out


def load_record(lc: LoadedConfig) -> Record:
    """Load and validate the record named by the config (columns renamed to model names)."""
    dc = lc.cfg.data
    path = lc.data_path
    f = str(path)
    if not path.is_file():
        raise DataError("data file not found (data.path is relative to the config's folder)", file=f)
    cols = _read_table(path, dc.format)
    log: list[str] = []

    def column(name: str, role: str) -> np.ndarray:
        if name not in cols:
            avail = ", ".join(list(cols)[:12]) or "(none)"
            raise DataError(f"column {name!r} ({role}) not found; columns: {avail}", file=f)
        v = cols[name]
        if isinstance(v, tuple):
            raise DataError(f"column {name!r} has a non-numeric value {v[2]!r} at row {v[1]}", file=f)
        bad = np.flatnonzero(~np.isfinite(v))
        if len(bad):
            raise DataError(f"column {name!r} has {len(bad)} NaN/inf value(s), first at row {bad[0]}; "
                            "clean or interpolate the record first", file=f)
        return v

    ins = {model: column(c, "input") for c, model in lc.input_map.items()}
    outs = {model: column(c, "output") for c, model in lc.output_map.items()}
    n = len(next(iter(outs.values())))
    if n < dc.min_samples:
        raise DataError(f"only {n} samples; at least {dc.min_samples} are needed (data.min_samples)", file=f)
    if dc.time is not None:
        t = column(dc.time, "time")
        d = np.diff(t)
        if np.any(d <= 0):
            i = int(np.flatnonzero(d <= 0)[0]) + 1
            raise DataError(f"time column {dc.time!r} is not strictly increasing at row {i} "
                            f"({t[i - 1]!r} then {t[i]!r})", file=f)
        dt = float(np.median(d))
        jitter = float(np.max(np.abs(d - dt)) / dt)
        if jitter > dc.max_jitter:
            i = int(np.argmax(np.abs(d - dt)))
            raise DataError(f"non-uniform sampling: interval at row {i + 1} is {d[i]:.6g} s against a median "
                            f"of {dt:.6g} s ({100 * jitter:.2f} % off; data.max_jitter allows "
                            f"{100 * dc.max_jitter:.2f} %); resample the record first", file=f)
        if jitter > 1e-6:
            log.append(f"sampling jitter up to {100 * jitter:.3g} % accepted; median dt = {dt:.6g} s used")
    else:
        dt = float(dc.sample_time)
        t = np.arange(n) * dt
    for name, u in ins.items():
        if np.ptp(u) == 0:
            raise DataError(f"input {name!r} is constant ({u[0]!r}); a constant input excites nothing", file=f)
    return Record(t=np.asarray(t, float), dt=dt, inputs=ins, outputs=outs, sha256=file_sha256(path),
                  path=f, log=log)


def make_split(lc: LoadedConfig, n: int) -> Split:
    s = lc.cfg.split
    f = str(lc.path)
    if s.estimation is not None:
        est = (s.estimation[0], n if s.estimation[1] is None else min(s.estimation[1], n))
        val = (s.validation[0], n if s.validation[1] is None else min(s.validation[1], n))
        for key, (a, b) in (("split.estimation", est), ("split.validation", val)):
            if a >= n or b - a < 10:
                raise DataError(f"range [{a}, {b}) holds fewer than 10 of the record's {n} samples",
                                file=f, key=key)
        if max(est[0], val[0]) < min(est[1], val[1]):
            raise DataError(f"estimation {list(est)} and validation {list(val)} overlap", file=f, key="split")
    else:
        nv = int(round(n * s.validation_fraction))
        est, val = (0, n - nv), (n - nv, n)
        if nv < 10 or n - nv < 10:
            raise DataError(f"validation_fraction {s.validation_fraction} leaves fewer than 10 samples "
                            "on one side", file=f, key="split.validation_fraction")
    return Split(est, val)


def remove_means(rec: Record, split: Split) -> None:
    """Subtract each signal's mean over the estimation part (data.remove_mean)."""
    sl = split.est_slice()
    for d in (rec.inputs, rec.outputs):
        for k in d:
            m = float(np.mean(d[k][sl]))
            d[k] = d[k] - m
            rec.means[k] = m
    rec.log.append("means over the estimation part removed: "
                   + ", ".join(f"{k}={v:.6g}" for k, v in rec.means.items()))


def apply_prefilters(rec: Record, steps, file: str) -> list[dict]:
    """Apply the config's prefilter steps (pipeline.prefilter) in order; returns the log entries.
    ``decimate`` acts on every signal and on the time axis; other steps on ``signals`` (default all)."""
    from .errors import InputError
    from .prefilter import Prefilter
    log = []
    for i, st in enumerate(steps):
        key = f"prefilter[{i}]"
        names = st.signals or list(rec.inputs) + list(rec.outputs)
        if st.name == "decimate":
            names = list(rec.inputs) + list(rec.outputs)
        step = Prefilter(st.name, dict(st.params))
        warns, info = [], {}
        try:
            for d in (rec.inputs, rec.outputs):
                for k in d:
                    if k in names:
                        res = step.apply(d[k], rec.dt)
                        d[k] = np.asarray(res.y, float)
                        warns += [f"{k}: {w}" for w in res.warnings]
                        info = res.info or info
        except InputError as exc:
            raise DataError(str(exc), file=file, key=key) from None
        if st.name == "decimate":
            q = int(st.params.get("q", 1))
            rec.t = rec.t[::q][: len(next(iter(rec.outputs.values())))]
            rec.dt = rec.dt * q
        entry = {"name": st.name, "params": dict(st.params), "signals": names, "warnings": warns, "info": info}
        log.append(entry)
        rec.log.append(f"prefilter {st.name} {dict(st.params)} on {', '.join(names)}"
                       + (f" (warnings: {'; '.join(warns)})" if warns else ""))
    return log
