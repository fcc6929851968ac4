"""Hostile data inputs (files, sizes, record lengths, formats, separate records, prefilters): the real
CLI in a subprocess (tests/hostile/harness.py: time and memory bound) must exit 2 with one ``error:``
line naming the file and the column or key, no traceback, and leave the folder exactly as it was."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import scipy.io
import yaml

from tests.hostile.harness import assert_bad_input, run_cli, snapshot

N = 400
MODEL = {"states": ["x", "v"], "inputs": ["u"], "params": {"m": 1.0, "c": 0.6, "k": 4.0}, "free": ["c", "k"],
         "equations": {"x": "v", "v": "(u - c*v - k*x)/m"}}


def _frame(n=N, seed=0) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    return pd.DataFrame({"t": np.arange(n) * 0.02, "u": rng.standard_normal(n), "x": rng.standard_normal(n)})


def _write_mat_v73(path: Path) -> None:
    # the 128-byte MAT header of a v7.3 file: text, subsystem offset, version 0x0200, endian "IM"
    path.write_bytes(b"MATLAB 7.3 MAT-file, Platform: GLNXA64".ljust(116) + b"\0" * 8 + b"\x00\x02IM" + b"\0" * 512)


# Each case: (prepare(dir) -> data-section changes and extra top-level config, strings the message names).
# "{dir}" in an expected string is the case's folder; "{cfg}" the config file.
def c_directory(d):
    (d / "recdir").mkdir()
    return {"path": "recdir"}, {}, ["{dir}/recdir", "data.path", "is a directory"]


def c_empty(d):
    (d / "rec.csv").write_bytes(b"")
    return {}, {}, ["{dir}/rec.csv", "data.path", "empty"]


def c_header_only(d):
    (d / "rec.csv").write_text("t,u,x\n")
    return {}, {}, ["{dir}/rec.csv", "no data rows"]


def c_binary_as_csv(d):
    (d / "rec.csv").write_bytes(np.random.default_rng(1).bytes(5000) + b"\0")
    return {}, {}, ["{dir}/rec.csv", "data.path", "binary"]


def c_parquet_named_csv(d):
    _frame().to_parquet(d / "rec.csv")
    return {}, {}, ["{dir}/rec.csv", "data.path", "Parquet file"]


def c_fifo(d):
    (d / "rec.csv").unlink()
    os.mkfifo(d / "rec.csv")   # opening it for reading would block forever
    return {}, {}, ["{dir}/rec.csv", "data.path", "not a regular file"]


def c_too_many_rows(d):
    return {"max_samples": 100}, {}, ["{dir}/rec.csv", "data.max_samples = 100"]


def c_not_utf8(d):
    (d / "rec.csv").write_bytes("t,u,x,temp\u00e9rature\n".encode("latin-1") + b"0,1,2,3\n")
    return {}, {}, ["{dir}/rec.csv", "not UTF-8"]


def c_duplicate_header(d):
    df = _frame()
    (d / "rec.csv").write_text("t,u,x,x\n" + "".join(f"{a},{b},{c},{c}\n" for a, b, c in df.to_numpy()))
    return {}, {}, ["{dir}/rec.csv", "column 'x' appears 2 times"]


def c_header_with_spaces(d):
    df = _frame()
    (d / "rec.csv").write_text("t, u, x\n" + "".join(f"{a},{b},{c}\n" for a, b, c in df.to_numpy()))
    return {}, {}, ["{dir}/rec.csv", "column 'u' (input) not found", "did you mean ' u'"]


def c_two_columns_one_name(d):
    df = _frame()
    df["x2"] = df["x"]
    df.to_csv(d / "rec.csv", index=False)
    return {"outputs": {"x": "x", "x2": "x"}}, {}, ["{cfg}", "data.outputs", "'x' and 'x2' both map to 'x'"]


def c_time_holds_dates(d):
    df = _frame()
    df["t"] = pd.date_range("2024-03-01 08:00", periods=N, freq="20ms").astype(str)
    df.to_csv(d / "rec.csv", index=False)
    return {}, {}, ["{dir}/rec.csv", "time column 't' holds dates", "give seconds"]


def c_time_holds_text(d):
    df = _frame().astype({"t": object})
    df.loc[7, "t"] = "soon"
    df.to_csv(d / "rec.csv", index=False)
    return {}, {}, ["{dir}/rec.csv", "time column 't' holds text ('soon' at row 7)"]


def c_parquet_time_timestamps(d):
    df = _frame()
    df["t"] = pd.date_range("2024-03-01", periods=N, freq="20ms")
    df.to_parquet(d / "rec.parquet")
    return {"path": "rec.parquet"}, {}, ["{dir}/rec.parquet", "time column 't' holds dates"]


def c_sample_time_inf(d):
    return {"time": None, "sample_time": float("inf")}, {}, ["{cfg}", "data.sample_time", "finite"]


def c_sample_time_nan(d):
    return {"time": None, "sample_time": float("nan")}, {}, ["{cfg}", "data.sample_time", "finite"]


def c_mat_lengths_differ(d):
    df = _frame()
    scipy.io.savemat(d / "rec.mat", {"t": df.t.to_numpy()[None, :], "u": df.u.to_numpy()[None, :],
                                     "x": df.x.to_numpy()[: N - 3, None]})
    return {"path": "rec.mat"}, {}, ["{dir}/rec.mat", "vectors differ in length", "'x' (output) has 397"]


def c_mat_v73(d):
    _write_mat_v73(d / "rec.mat")
    return {"path": "rec.mat"}, {}, ["{dir}/rec.mat", "v7.3"]


def c_mat_not_a_mat(d):
    _frame().to_csv(d / "rec.mat", index=False)
    return {"path": "rec.mat"}, {}, ["{dir}/rec.mat", "cannot read as mat"]


def c_mat_3d_variable(d):
    df = _frame()
    scipy.io.savemat(d / "rec.mat", {"t": df.t.to_numpy(), "u": df.u.to_numpy(), "x": np.zeros((2, 3, N))})
    return {"path": "rec.mat"}, {}, ["{dir}/rec.mat", "variable 'x'", "not a signal"]


def c_mat_complex(d):
    df = _frame()
    scipy.io.savemat(d / "rec.mat", {"t": df.t.to_numpy(), "u": df.u.to_numpy() * (1 + 1j), "x": df.x.to_numpy()})
    return {"path": "rec.mat"}, {}, ["{dir}/rec.mat", "variable 'u'", "not real numbers"]


def c_mat_too_many_samples(d):
    df = _frame()
    scipy.io.savemat(d / "rec.mat", {"sig": df.to_numpy().T}, do_compression=True)   # 3 x 400
    return ({"path": "rec.mat", "time": "sig_1", "inputs": {"sig_2": "u"}, "outputs": {"sig_3": "x"},
             "max_samples": 399}, {}, ["{dir}/rec.mat", "'sig' holds 400 samples", "data.max_samples"])


def c_table_without_columns(d):
    np.savetxt(d / "rec.dat", _frame().to_numpy())
    return {"path": "rec.dat"}, {}, ["{dir}/rec.dat", "data.columns"]


def c_table_column_count(d):
    np.savetxt(d / "rec.dat", _frame().to_numpy())
    # two names for three fields (one column as input and output is refused first: load_config)
    return ({"path": "rec.dat", "format": "table", "columns": ["u", "x"], "time": None, "sample_time": 0.02},
            {}, ["{dir}/rec.dat", "data.columns names 2 columns", "holds 3 fields"])


def c_table_long_line(d):
    lines = [" ".join(f"{v:.6f}" for v in r) for r in _frame().to_numpy()]
    lines[123] += " 1.0"
    (d / "rec.dat").write_text("\r\n".join(lines) + "\r\n")
    return {"path": "rec.dat", "columns": ["t", "u", "x"]}, {}, ["{dir}/rec.dat", "line 124"]


def c_columns_for_csv(d):
    return {"columns": ["t", "u", "x"]}, {}, ["{dir}/rec.csv", "data.columns", "only for headerless tables"]


def c_skip_rows_for_parquet(d):
    _frame().to_parquet(d / "rec.parquet")
    return {"path": "rec.parquet", "skip_rows": 2}, {}, ["{dir}/rec.parquet", "data.skip_rows", "read as parquet"]


def c_decimal_is_delimiter(d):
    return {"decimal": ","}, {}, ["{dir}/rec.csv", "data.decimal"]


def c_decimate_below_min_samples(d):
    return {}, {"prefilter": [{"name": "decimate", "params": {"q": 10}}]}, \
        ["{cfg}", "prefilter[0]", "after decimation by 10", "40 samples", "data.min_samples"]


def c_svf_output_out_of_range(d):
    step = {"name": "state_variable_filter", "params": {"order": 2, "omega_c": 10.0, "output": 5}}
    return {}, {"prefilter": [step]}, ["{cfg}", "prefilter[0].params.output", "out of range"]


def c_validation_missing(d):
    return {"validation": {"path": "val.csv"}}, {}, ["{dir}/val.csv", "data.validation.path", "not found"]


def c_validation_other_outputs(d):
    return {"validation": {"outputs": {"x": "v"}}}, {}, ["{cfg}", "data.validation.outputs", "same model outputs"]


def c_validation_other_rate(d):
    df = _frame(300, 1)
    df["t"] = np.arange(300) * 0.05
    df.to_csv(d / "val.csv", index=False)
    return {"validation": {"path": "val.csv"}}, {}, ["{dir}/val.csv", "data.validation", "sampled every 0.05 s"]


def c_validation_column_missing(d):
    _frame(300, 1).drop(columns=["x"]).to_csv(d / "val.csv", index=False)
    return {"validation": {"path": "val.csv"}}, {}, ["{dir}/val.csv", "data.validation", "column 'x' (output) not found"]


def c_validation_and_split_ranges(d):
    _frame(300, 1).to_csv(d / "val.csv", index=False)
    return ({"validation": {"path": "val.csv"}}, {"split": {"estimation": [0, 200], "validation": [200, None]}},
            ["{cfg}", "split", "cannot be combined"])


def c_experiments_without_validation(d):
    return {"experiments": [{"role": "estimation"}]}, {}, ["{cfg}", "data.experiments", "no experiment has role validation"]


def c_experiment_without_role(d):
    return {"experiments": [{"role": "estimation"}, {"path": "rec.csv"}]}, {}, ["{cfg}", "data.experiments[1].role"]


CASES = {name[2:]: fn for name, fn in sorted(globals().items()) if name.startswith("c_")}


def _run_case(tmp_path: Path, name: str):
    d = tmp_path / "case"
    d.mkdir()
    _frame().to_csv(d / "rec.csv", index=False)
    data_changes, extra, expected = CASES[name](d)
    data = {"path": "rec.csv", "time": "t", "inputs": ["u"], "outputs": ["x"]}
    for k, v in data_changes.items():
        if v is None:
            data.pop(k, None)
        else:
            data[k] = v
    cfg = {"name": "hostile", "seed": 0, "data": data, "model": MODEL, **extra}
    (d / "c.yaml").write_text(yaml.safe_dump(cfg))
    before = snapshot(d)
    out = tmp_path / "r"      # its parent exists: --out refuses a missing parent folder
    res = run_cli("report", str(d / "c.yaml"), "--out", str(out))
    return res, [e.replace("{dir}", str(d)).replace("{cfg}", str(d / "c.yaml")) for e in expected], d, before, out


@pytest.mark.parametrize("name", list(CASES))
def test_hostile_data_input(tmp_path, name):
    res, expected, d, before, out = _run_case(tmp_path, name)
    assert_bad_input(res, *expected)
    assert snapshot(d) == before, "the run changed the case folder"
    assert not out.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["case"]


def test_file_above_the_default_size_bound_is_refused_before_reading(tmp_path):
    """A sparse file one byte above the default data.max_bytes (2 GiB): refused from os.stat alone,
    quickly and within the harness's memory bound; the file is left as it was."""
    d = tmp_path / "case"
    d.mkdir()
    big = tmp_path / "big" / "rec.csv"
    big.parent.mkdir()
    with open(big, "wb") as fh:
        fh.write(b"t,u,x\n")
        fh.truncate((2 << 30) + 1)
    st = big.stat()
    cfg = {"name": "hostile", "data": {"path": str(big), "time": "t", "inputs": ["u"], "outputs": ["x"]}, "model": MODEL}
    (d / "c.yaml").write_text(yaml.safe_dump(cfg))
    before = snapshot(d)
    res = run_cli("report", str(d / "c.yaml"), "--out", str(tmp_path / "r"), timeout=60)
    assert_bad_input(res, str(big), "data.path", "2 GiB, more than data.max_bytes (2 GiB)")
    assert snapshot(d) == before and sorted(p.name for p in tmp_path.iterdir()) == ["big", "case"]
    assert (big.stat().st_size, big.stat().st_mtime_ns) == (st.st_size, st.st_mtime_ns)
