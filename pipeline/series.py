"""``simulation.csv``: the measured and simulated series of a run, one row per sample.

A run folder's summary holds numbers only; this table lets a user plot the measured output against the
models in their own tool (``pandas.read_csv(path)`` with its defaults reads it). Rows are the samples of
the record the run analysed, in order (row *k* is sample *k*; with several records, their
concatenation, estimation records first), after the prefilter steps and ``data.remove_mean``: the
signals the fits saw. Columns, in this order:

- ``t``: time in seconds as the record gives it (it restarts with each record of several);
- ``part``: ``estimation`` or ``validation`` (the split of ``summary.json``'s ``data.estimation`` /
  ``data.validation``), ``unused`` for samples in neither (e.g. a gap between the two ranges; a
  ``split.warmup`` range that is not itself validation is ``unused`` too);
- ``record``, only when the run read several records (``data.validation``, ``data.experiments``): the
  name of the record the sample comes from (``estimation``, ``validation``, an experiment's ``name``);
- each model input, by its model name (``model.inputs``);
- per model output ``y`` (``summary.json``'s ``data.outputs``, in order): ``y`` measured, ``y_nominal``
  the **free-run simulation** (not one-step prediction) of the fitted nominal model, ``y_final`` the
  free-run simulation of the final model after the accepted findings (equal to ``y_nominal`` when there
  is none).

The simulated columns are the fits' own ``FitResult.Yhat`` arrays, the ones ``summary.json``'s
``rmse_sim`` and ``fit_percent`` are computed from (:func:`pipeline.runs.model_block`): on the
estimation rows the fitted (warm-up) simulation, elsewhere each record's simulation from its start. So
the RMSE of ``y − y_nominal`` over the ``estimation`` rows is ``nominal.estimation.rmse_sim`` and over
the ``validation`` rows ``nominal.validation.rmse_sim`` (several outputs: pooled over them), to the
10 significant digits written.

Format: comma-separated, a header line, no comment or index column, ``\\n`` line endings, UTF-8; every
number as ``%.10g`` (10 significant digits, the precision of ``summary.json``); a NaN is written as
``nan`` and an infinity as ``inf``/``-inf`` (both read back by pandas' defaults); a record name holding
a comma, a quote or a line break is quoted (RFC 4180). The bytes depend only on the numbers, so two runs
of the same config on the same data write the same file. About 80 bytes a row with one input and one
output: 10.6 MB written in ~0.25 s for Silverbox's 131 072 samples. Column names are unique: a model
input or output named like an earlier column (an input called ``part`` or ``record``, an input ``x_nominal``
beside an output ``x``) is written with its role appended, ``part_input`` or ``x_nominal_measured``
(then ``_2``, ``_3``... should that be taken too), so a reader never has to guess which ``part`` is which.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # annotations only: nothing of these modules runs here
    from .data import Record, Segment
    from .diagnostics.engine import Diagnosis
    from .fit import FitResult, Problem

FILENAME = "simulation.csv"
NUMBER = "%.10g"
PARTS = ("estimation", "validation", "unused")


@dataclass
class SeriesTable:
    """The table's columns: ``header[i]`` names ``columns[i]`` (floats, or strings for part/record)."""

    header: list[str]
    columns: list[np.ndarray]

    @property
    def n_rows(self) -> int:
        return len(self.columns[0]) if self.columns else 0


def part_labels(n: int, est: tuple[int, int], val: tuple[int, int]) -> np.ndarray:
    """(n,) ``estimation`` / ``validation`` / ``unused`` per sample for the split's [start, stop) ranges."""
    lab = np.full(n, PARTS[2], dtype=object)
    lab[slice(*val)] = PARTS[1]
    lab[slice(*est)] = PARTS[0]
    return lab


def record_labels(n: int, segments: Sequence[Segment]) -> np.ndarray:
    """(n,) the name of the record (segment) each sample comes from."""
    lab = np.full(n, "", dtype=object)
    for g in segments:
        lab[g.start:g.stop] = g.name
    return lab


def build_table(prob: Problem, nominal: FitResult, final: FitResult, inputs: Sequence[str],
                segments: Sequence[Segment] = ()) -> SeriesTable:
    """The columns of ``simulation.csv`` (see the module docstring). ``inputs`` name ``prob.U``'s
    columns (the model's inputs; none for a model without inputs); ``segments`` are the record's
    experiments, and a ``record`` column is added when there are several."""
    n = len(prob.t)
    for f in (nominal, final):
        if f.Yhat.shape != prob.Y.shape:
            raise ValueError(f"simulated outputs {f.Yhat.shape} do not match the measured {prob.Y.shape}")
    header = ["t", "part"]
    cols: list[np.ndarray] = [np.asarray(prob.t, float), part_labels(n, prob.split.est, prob.split.val)]
    if len(segments) > 1:
        header.append("record")
        cols.append(record_labels(n, segments))
    for j, name in enumerate(inputs):
        header.append(_unique(name, "input", header))
        cols.append(np.asarray(prob.U[:, j], float))
    for i, name in enumerate(prob.out_names):
        for col, role in ((name, "measured"), (f"{name}_nominal", "nominal"), (f"{name}_final", "final")):
            header.append(_unique(col, role, header))
        cols += [np.asarray(prob.Y[:, i], float), np.asarray(nominal.Yhat[:, i], float),
                 np.asarray(final.Yhat[:, i], float)]
    return SeriesTable(header, cols)


def _unique(name: str, role: str, taken: Sequence[str]) -> str:
    """``name``, or ``name_<role>`` when an earlier column holds ``name`` (then ``_2``, ``_3``...)."""
    if name not in taken:
        return name
    base = f"{name}_{role}"
    out, k = base, 2
    while out in taken:
        out, k = f"{base}_{k}", k + 1
    return out


def _text(s: str) -> str:
    """One CSV text field: quoted (quotes doubled) only when it holds a separator, quote or line break."""
    return '"' + s.replace('"', '""') + '"' if any(c in s for c in ',"\r\n') else s


def to_csv(table: SeriesTable) -> bytes:
    """The table as CSV bytes (module docstring: ``%.10g``, ``nan``, ``\\n``, UTF-8). One ``%``
    format per row over Python lists: ~0.2 s for Silverbox's 131 072 rows of six columns."""
    fmts, values = [], []
    for col in table.columns:
        if col.dtype == object:
            fmts.append("%s")
            texts = col.tolist()
            quoted = {v: _text(str(v)) for v in set(texts)}   # a few distinct labels: quote each once
            values.append([quoted[v] for v in texts])
        else:
            fmts.append(NUMBER)
            values.append(col.tolist())
    row = ",".join(fmts)
    lines = [",".join(_text(h) for h in table.header)]
    lines += [row % r for r in zip(*values)]
    return ("\n".join(lines) + "\n").encode("utf-8")


def simulation_csv(prob: Problem, diag: Diagnosis, rec: Record) -> bytes:
    """``simulation.csv`` of an analysed run: the nominal and final fits of ``diag`` on ``prob``, the
    inputs named as the nominal model names them, the records of ``rec``."""
    inputs = list(diag.nominal.model.inputs)
    return to_csv(build_table(prob, diag.nominal, diag.final, inputs, rec.segments))
