"""Records: loading (pipeline.loaders: CSV, headerless tables, Parquet, MATLAB .mat), validation,
separate estimation/validation records, fingerprint, split, prefilters.

Policies (each explicit; violations are :class:`DataError` naming file and column):
* missing column, non-numeric values, NaN/inf: error with the first offending row;
* vectors of one record (time, inputs, outputs) of different lengths: error naming both and their
  lengths (a .mat file can hold vectors of any length);
* time not strictly increasing: error with the first offending row;
* sampling intervals deviating from the median by more than ``data.max_jitter`` (relative): error that
  says by how much; smaller jitter is accepted, logged, and the median interval is used;
* fewer than ``data.min_samples`` samples (in any record, and again after ``decimate``), or a constant
  input: error;
* files are bounded before they are read: ``data.max_bytes`` (default 2 GiB) and ``data.max_samples``
  rows (default 50 million); see :mod:`pipeline.loaders`.

Separate records (contract §4). ``data.validation: {...}`` adds one validation record to the one
``data`` describes (the estimation record); ``data.experiments: [{..., role: estimation|validation}]``
lists every record instead (``data`` then only gives defaults). An experiment's missing keys are
taken from ``data`` (``path`` too, so side-by-side columns of one file work); ``time`` and
``sample_time`` go together: giving either replaces both. Every record must map its columns to the
same model inputs and outputs and be sampled at the same interval (within ``data.max_jitter``).
The :class:`Record` holds the records concatenated, estimation ones first, and one
:class:`Segment` per record; ``Record.t`` restarts in each segment (each record's own time).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .config import DECIMATE_SIGNALS, LoadedConfig
from .errors import ConfigError, DataError
from .hashing import file_sha256  # noqa: F401 - imported from here by runs, assignment
from .loaders import ReadSpec, read_columns


@dataclass(frozen=True)
class Segment:
    """Rows ``[start, stop)`` of the concatenated record that came from one experiment."""

    name: str            # "record", "estimation", "validation", "experiment 2", ...
    start: int
    stop: int
    role: str | None     # "estimation" | "validation" | None (a single plain record: the split decides)

    @property
    def n(self) -> int:
        return self.stop - self.start

    def rows(self) -> slice:
        return slice(self.start, self.stop)


@dataclass
class Record:
    """One measured record (or several, concatenated), columns renamed to the model's names."""

    t: np.ndarray                       # (N,) seconds, uniform within each segment, restarting per segment
    dt: float
    inputs: dict[str, np.ndarray]       # model input name -> (N,)
    outputs: dict[str, np.ndarray]      # state / declared output name -> (N,)
    sha256: str
    path: str
    log: list[str] = field(default_factory=list)
    means: dict[str, float] = field(default_factory=dict)  # removed means (remove_mean)
    segments: list[Segment] = field(default_factory=list)  # default: one Segment("record", 0, n, None)
    sources: list[dict] = field(default_factory=list)      # per segment: name, role, path, sha256

    def __post_init__(self) -> None:
        if not self.segments:
            self.segments = [Segment("record", 0, self.n, None)]

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def has_roles(self) -> bool:
        """True when the records themselves say which rows estimate and which validate."""
        return any(s.role is not None for s in self.segments)

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


MAX_MAGNITUDE = 1e75   # |values| above this overflow the 4th powers (kurtosis, HAC bandwidths)
MIN_MAGNITUDE = 1e-75  # a column whose largest |value| is below this underflows them (1e-160: squares of 1e-320)


def records_sha256(entries: list[tuple[str, str | None]]) -> str:
    """Fingerprint of several files: sha256 of the sorted lines ``"<file sha256> <role>"``. A single
    plain record keeps its file's own sha256 (unchanged run ids)."""
    lines = sorted(f"{sha} {role}" for sha, role in entries)
    return hashlib.sha256("\n".join(lines).encode()).hexdigest()


# ------------------------------------------------------------------------------------ sources
@dataclass(frozen=True)
class Source:
    """One record to load, its keys resolved (an experiment's own, else ``data``'s)."""

    name: str
    role: str | None
    key: str                      # config key: "data", "data.validation", "data.experiments[1]"
    path: Path
    time: str | None
    sample_time: float | None
    input_map: dict[str, str]     # column -> model input
    output_map: dict[str, str]    # column -> state / declared output
    spec: ReadSpec


_READ_KEYS = ("format", "columns", "delimiter", "decimal", "comment", "skip_rows")


def _as_map(v) -> dict[str, str]:
    return {c: c for c in v} if isinstance(v, list) else dict(v)


def _source(lc: LoadedConfig, exp, name: str, role: str | None, key: str) -> Source:
    dc = lc.cfg.data
    f = str(lc.path)

    def pick(k):
        own = getattr(exp, k, None) if exp is not None else None
        return own if own is not None else getattr(dc, k)

    if exp is not None and (exp.time is not None or exp.sample_time is not None):
        if exp.time is not None and exp.sample_time is not None:
            raise ConfigError("give time or sample_time, not both", file=f, key=key)
        time, sample_time = exp.time, exp.sample_time
    else:
        time, sample_time = dc.time, dc.sample_time
    p = Path(pick("path"))
    path = p if p.is_absolute() else lc.path.parent / p
    rd = {k: pick(k) for k in _READ_KEYS}
    spec = ReadSpec(format=rd["format"], columns=tuple(rd["columns"]) if rd["columns"] else None,
                    delimiter=rd["delimiter"], decimal=rd["decimal"] or ".", comment=rd["comment"],
                    skip_rows=rd["skip_rows"] or 0, max_bytes=dc.max_bytes, max_samples=dc.max_samples)
    imap, omap = _as_map(pick("inputs")), _as_map(pick("outputs"))
    for what, m, want in (("inputs", imap, lc.input_map), ("outputs", omap, lc.output_map)):
        if sorted(m.values()) != sorted(want.values()):
            raise ConfigError(f"maps columns to {sorted(m.values())}, data.{what} to {sorted(want.values())}; "
                              f"every record must give the same model {what}", file=f, key=f"{key}.{what}")
    return Source(name, role, key, path, time, sample_time, imap, omap, spec)


def sources(lc: LoadedConfig) -> list[Source]:
    """The records the config names, estimation ones first (config errors name the key)."""
    dc = lc.cfg.data
    f = str(lc.path)
    if dc.validation is not None and dc.experiments is not None:
        raise ConfigError("give data.validation or data.experiments, not both", file=f, key="data")
    if dc.validation is not None:
        v = dc.validation
        if v.role == "estimation":
            raise ConfigError("the validation record cannot have role estimation", file=f, key="data.validation.role")
        return [_source(lc, None, "estimation", "estimation", "data"),
                _source(lc, v, v.name or "validation", "validation", "data.validation")]
    if dc.experiments is not None:
        out, names = [], set()
        for i, e in enumerate(dc.experiments):
            key = f"data.experiments[{i}]"
            if e.role is None:
                raise ConfigError("role is required: estimation or validation", file=f, key=f"{key}.role")
            name = e.name or f"experiment {i + 1}"
            if name in names:
                raise ConfigError(f"experiment name {name!r} is used twice", file=f, key=f"{key}.name")
            names.add(name)
            out.append(_source(lc, e, name, e.role, key))
        roles = {s.role for s in out}
        for role in ("estimation", "validation"):
            if role not in roles:
                raise ConfigError(f"no experiment has role {role}; give at least one estimation and one "
                                  "validation experiment", file=f, key="data.experiments")
        return [s for s in out if s.role == "estimation"] + [s for s in out if s.role == "validation"]
    return [_source(lc, None, "record", None, "data")]


# ------------------------------------------------------------------------------------ loading
@dataclass
class _Part:
    t: np.ndarray
    dt: float
    inputs: dict[str, np.ndarray]
    outputs: dict[str, np.ndarray]
    sha256: str
    log: list[str]


def _load_source(src: Source, dc, plain: bool) -> _Part:
    """Read and check one record: lengths, finiteness, time axis, size."""
    f = str(src.path)
    key = None if src.key == "data" else src.key
    needed: dict[str, str] = {}           # checked in this order: inputs, outputs, time (as before)
    for c in src.input_map:
        needed.setdefault(c, "input")
    for c in src.output_map:
        needed.setdefault(c, "output")
    if src.time is not None:
        needed.setdefault(src.time, "time")
    cols = read_columns(src.path, src.spec, needed, time=src.time, key=key)
    log: list[str] = []
    ref = next(iter(needed))
    for name in needed:
        if len(cols[name]) != len(cols[ref]):
            raise DataError(f"vectors differ in length: column {name!r} ({needed[name]}) has {len(cols[name])} "
                            f"samples, column {ref!r} ({needed[ref]}) has {len(cols[ref])}", file=f, key=key)

    def column(name: str) -> np.ndarray:
        v = cols[name]
        bad = np.flatnonzero(~np.isfinite(v))
        if len(bad):
            raise DataError(f"column {name!r} has {len(bad)} NaN/inf value(s), first at row {bad[0]} (data "
                            "rows counted from 0; an empty or missing cell counts too); clean or interpolate "
                            "the record first", file=f, key=key)
        big = float(np.max(np.abs(v))) if len(v) else 0.0
        if big > MAX_MAGNITUDE:
            raise DataError(f"column {name!r} holds values up to {big:.3g} in magnitude; the statistics raise "
                            f"residuals to the 4th power, which overflows a float beyond {MAX_MAGNITUDE:.0e}: "
                            "rescale the column (e.g. other units)", file=f, key=key)
        if 0.0 < big < MIN_MAGNITUDE:
            raise DataError(f"column {name!r} holds values no larger than {big:.3g} in magnitude; the statistics "
                            f"raise residuals to the 4th power, which underflows a float below {MIN_MAGNITUDE:.0e}: "
                            "rescale the column (e.g. other units)", file=f, key=key)
        return v

    ins = {model: column(c) for c, model in src.input_map.items()}
    outs = {model: column(c) for c, model in src.output_map.items()}
    n = len(cols[ref])
    if n < dc.min_samples:
        raise DataError(f"only {n} samples; at least {dc.min_samples} are needed (data.min_samples)", file=f, key=key)
    if src.time is not None:
        t = column(src.time)
        d = np.diff(t)
        if np.any(d <= 0):
            i = int(np.flatnonzero(d <= 0)[0]) + 1
            raise DataError(f"time column {src.time!r} is not strictly increasing at row {i} "
                            f"({float(t[i - 1]):.10g} then {float(t[i]):.10g})", file=f, key=key)
        dt = float(np.median(d))
        jitter = max(float(d.max()) - dt, dt - float(d.min())) / dt   # max |d - dt| / dt, no temporaries
        if not np.isfinite(dt) or not np.isfinite(jitter):
            raise DataError(f"time column {src.time!r} gives a sampling interval of {dt!r} s; give seconds",
                            file=f, key=key)
        if jitter > dc.max_jitter:
            i = int(np.argmax(np.abs(d - dt)))
            raise DataError(f"non-uniform sampling: interval at row {i + 1} is {d[i]:.6g} s against a median "
                            f"of {dt:.6g} s ({100 * jitter:.3g} % off; data.max_jitter allows "
                            f"{100 * dc.max_jitter:.3g} %); resample the record first", file=f, key=key)
        if jitter > 1e-6:
            log.append(f"sampling jitter up to {100 * jitter:.3g} % accepted; median dt = {dt:.6g} s used")
    else:
        dt = float(src.sample_time)
        t = np.arange(n) * dt
    if plain:
        _check_excited(ins, slice(None), f, key, outs=outs,
                       columns={v: str(k) for k, v in {**src.input_map, **src.output_map}.items()})
    return _Part(np.asarray(t, float), dt, ins, outs, file_sha256(src.path), log)


def _check_excited(ins: dict[str, np.ndarray], rows: slice, f: str, key: str | None, where: str = "",
                   outs: dict[str, np.ndarray] | None = None, columns: dict[str, str] | None = None) -> None:
    """A constant input excites nothing; a constant output has nothing to identify (a model that holds it
    fits with a residual of exactly zero, whose log-likelihood is not finite). ``columns``: the file's
    column of each model name, named in the message when it differs."""
    def named(kind: str, name: str) -> str:
        col = (columns or {}).get(name, name)
        return f"column {col!r} ({kind} {name!r})" if col != name else f"{kind} {name!r}"

    for name, u in ins.items():
        if np.ptp(u[rows]) == 0:
            raise DataError(f"{named('input', name)} is constant{where} ({float(u[rows][0]):.10g}); a constant input "
                            "excites nothing: write its value into the equations in place of the input, or add "
                            "a record that moves it (data.experiments)", file=f, key=key)
    for name, y in (outs or {}).items():
        if np.ptp(y[rows]) == 0:
            raise DataError(f"{named('output', name)} is constant{where} ({float(y[rows][0]):.10g}); a constant "
                            "output holds nothing to identify", file=f, key=key)


def _same_samples(a: "_Part", b: "_Part") -> bool:
    """The two parts hold the same input and output samples (a record given in two roles)."""
    return len(a.t) == len(b.t) and all(np.array_equal(a.inputs[k], b.inputs[k]) for k in a.inputs) and \
        all(np.array_equal(a.outputs[k], b.outputs[k]) for k in a.outputs)


def load_record(lc: LoadedConfig) -> Record:
    """Load and validate the record(s) named by the config (columns renamed to model names)."""
    dc = lc.cfg.data
    srcs = sources(lc)
    plain = len(srcs) == 1 and srcs[0].role is None
    parts = [_load_source(s, dc, plain) for s in srcs]
    info = [{"name": s.name, "role": s.role, "path": str(s.path), "sha256": p.sha256} for s, p in zip(srcs, parts)]
    if plain:
        p = parts[0]
        return Record(t=p.t, dt=p.dt, inputs=p.inputs, outputs=p.outputs, sha256=p.sha256, path=str(srcs[0].path),
                      log=p.log, sources=info)
    # a validation record with the estimation record's content (the same file, or a copy) would make every
    # validation number in-sample: the report's "data it never saw" would be false (an independent probe
    # found validation fit 98.6 % and gain intervals "on this validation input" for the fitted samples).
    # Compared by the samples read, not the file: one file may hold both records in different columns
    fitted = [(s, p) for s, p in zip(srcs, parts) if s.role == "estimation"]
    for s, p in zip(srcs, parts):
        e = next((es for es, ep in fitted if _same_samples(ep, p)), None) if s.role == "validation" else None
        if e is not None:
            raise DataError(f"the validation record {Path(s.path).name} holds the same samples as the estimation "
                            f"record {Path(e.path).name} "
                            f"({e.key}): every validation number would be measured on the samples that were "
                            "fitted; give a record that was not used for estimation, or give one record and let "
                            "split (e.g. split.validation_fraction) hold its end out", file=str(lc.path),
                            key=s.key)
    dt0 = parts[0].dt
    for s, p in zip(srcs[1:], parts[1:]):
        if abs(p.dt - dt0) > dc.max_jitter * dt0:
            raise DataError(f"record {s.name!r} is sampled every {p.dt:.6g} s, record {srcs[0].name!r} every "
                            f"{dt0:.6g} s; resample one of them", file=str(s.path), key=s.key)
    segments, start = [], 0
    for s, p in zip(srcs, parts):
        segments.append(Segment(s.name, start, start + len(p.t), s.role))
        start += len(p.t)
    cat = lambda key, name: np.concatenate([getattr(p, key)[name] for p in parts])  # noqa: E731
    ins = {k: cat("inputs", k) for k in parts[0].inputs}
    outs = {k: cat("outputs", k) for k in parts[0].outputs}
    est = [g for g in segments if g.role == "estimation"]
    _check_excited(ins, slice(est[0].start, est[-1].stop), str(srcs[0].path), None, " over the estimation records",
                   outs=outs)
    log = [m for p in parts for m in p.log]
    log.append("records: " + "; ".join(f"{g.name} ({g.role}) rows [{g.start}, {g.stop}) from {Path(s.path).name}"
                                       for g, s in zip(segments, srcs)))
    return Record(t=np.concatenate([p.t for p in parts]), dt=dt0, inputs=ins, outputs=outs,
                  sha256=records_sha256([(p.sha256, s.role) for s, p in zip(srcs, parts)]),
                  path=str(srcs[0].path), log=log, segments=segments, sources=info)


def make_split(lc: LoadedConfig, rec: "Record | int") -> Split:
    """Estimation and validation rows. With separate records (segments with roles) they are the rows of
    the estimation segments and of the validation ones (contiguous: estimation records come first), and
    ``split`` ranges or ``validation_fraction`` are an error; otherwise the ``split`` section decides.
    ``rec`` may be a plain sample count (no segments)."""
    s = lc.cfg.split
    f = str(lc.path)
    n = rec.n if isinstance(rec, Record) else int(rec)
    if isinstance(rec, Record) and rec.has_roles:
        given = [k for k in ("estimation", "validation", "validation_fraction")
                 if getattr(s, k) is not None and k in s.model_fields_set]
        if given:
            raise ConfigError(f"split.{given[0]} cannot be combined with separate estimation and validation "
                              "records (data.validation / data.experiments roles decide the split)",
                              file=f, key="split")
        est = [g for g in rec.segments if g.role == "estimation"]
        val = [g for g in rec.segments if g.role == "validation"]
        _check_warmup(s.warmup, est[0].start, rec, f)
        return Split((est[0].start, est[-1].stop), (val[0].start, val[-1].stop))
    if s.estimation is not None:
        for key, rng in (("split.estimation", s.estimation), ("split.validation", s.validation)):
            if rng is not None and rng[1] is not None and rng[1] > n:
                raise DataError(f"range [{rng[0]}, {rng[1]}) ends past the record's {n} samples; give null as "
                                "the end for 'to the end of the record'", file=f, key=key)
        est = (s.estimation[0], n if s.estimation[1] is None else s.estimation[1])
        val = (s.validation[0], n if s.validation[1] is None else s.validation[1])
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
    _check_warmup(s.warmup, est[0], rec, f)
    return Split(est, val)


def _check_warmup(warmup: int | None, e0: int, rec: "Record | int", f: str) -> None:
    """``split.warmup`` must fit before the estimation part within its own experiment: the fit simulates
    from ``warmup`` samples before it (``fit.Problem.from_record``), which cannot start before the
    experiment does. A longer one was silently cut to what was there (an independent probe: warm-up 500
    with the estimation part at sample 100 ran as warm-up 100, and 10**9 ran as none)."""
    if not warmup:
        return
    starts = [g.start for g in getattr(rec, "segments", []) or [] if g.start <= e0]
    room = e0 - max([0] + starts)
    if warmup > room:
        where = ("the start of the record" if not starts or max(starts) == 0 else
                 f"the start of its experiment (sample {max(starts)})")
        raise DataError(f"{warmup} samples of warm-up, but the estimation part starts {room} samples after "
                        f"{where}; at most {room}"
                        + ("" if room else " (there is nothing to simulate before it: remove split.warmup)"),
                        file=f, key="split.warmup")


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


def _check_prefilter_step(st, key: str, file: str) -> None:
    """Options :mod:`pipeline.prefilter` would index with, checked before use."""
    if st.name == "state_variable_filter" and "output" in st.params:
        out, order = st.params["output"], st.params.get("order")
        ok_order = isinstance(order, int) and not isinstance(order, bool) and order >= 1
        if isinstance(out, bool) or not isinstance(out, int) or out < 0 or (ok_order and out > order):
            rng = f"0..{order} (filtered derivatives of order 0 to {order})" if ok_order else "0..order"
            raise DataError(f"output index {out!r} is out of range; a state_variable_filter of order {order!r} "
                            f"gives outputs {rng}", file=file, key=f"{key}.params.output")


def apply_prefilters(rec: Record, steps, file: str, min_samples: int | None = None) -> list[dict]:
    """Apply the config's prefilter steps (pipeline.prefilter) in order; returns the log entries.
    ``decimate`` acts on every signal and on the time axis (a ``signals`` list on it is an error); other
    steps on ``signals`` (default all).
    Each step runs on every segment separately (a segment boundary is a break between experiments, so a
    filter must not carry one record's state into the next). After a ``decimate`` every segment must
    still hold ``min_samples`` samples (data.min_samples)."""
    from .errors import InputError
    from .prefilter import Prefilter
    log = []
    for i, st in enumerate(steps):
        key = f"prefilter[{i}]"
        _check_prefilter_step(st, key, file)
        if st.name == "decimate" and st.signals is not None:   # load_config refuses it too; it was ignored
            raise ConfigError(DECIMATE_SIGNALS, file=file, key=f"{key}.signals")
        names = st.signals or list(rec.inputs) + list(rec.outputs)
        step = Prefilter(st.name, dict(st.params))
        multi = len(rec.segments) > 1
        warns, info = [], {}
        pieces: dict[str, list[np.ndarray]] = {k: [] for d in (rec.inputs, rec.outputs) for k in d}
        try:
            for g in rec.segments:
                for d in (rec.inputs, rec.outputs):
                    for k in d:
                        x = d[k][g.rows()]
                        if k in names:
                            res = step.apply(x, rec.dt)
                            x = np.asarray(res.y, float)
                            warns += [f"{k}{f' ({g.name})' if multi else ''}: {w}" for w in res.warnings]
                            info = res.info or info
                        pieces[k].append(x)
        except InputError as exc:
            raise DataError(str(exc), file=file, key=key) from None
        for d in (rec.inputs, rec.outputs):
            for k in d:
                d[k] = np.concatenate(pieces[k]) if multi else pieces[k][0]
        if st.name == "decimate":
            q = int(st.params.get("q", 1))
            lengths = [len(p) for p in next(iter(pieces.values()))]
            t, segs, start = [], [], 0
            for g, m in zip(rec.segments, lengths):
                t.append(rec.t[g.rows()][::q][:m])
                segs.append(Segment(g.name, start, start + m, g.role))
                start += m
            rec.t = np.concatenate(t)
            rec.segments = segs
            rec.dt = rec.dt * q
            for g in segs:
                if min_samples is not None and g.n < min_samples:
                    what = f"segment {g.name!r}" if multi else "the record"
                    raise DataError(f"after decimation by {q}, {what} holds {g.n} samples; at least {min_samples} "
                                    "are needed (data.min_samples)", file=file, key=key)
        entry = {"name": st.name, "params": dict(st.params), "signals": names, "warnings": warns, "info": info}
        log.append(entry)
        rec.log.append(f"prefilter {st.name} {dict(st.params)} on {', '.join(names)}"
                       + (f" (warnings: {'; '.join(warns)})" if warns else ""))
    return log
