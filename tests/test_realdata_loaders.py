"""Real records of ../shared/datasets loaded as they are (no conversion): the DaISy headerless tables
(CRLF, tab or space separated, a trailing tab) and the cascaded tanks CSV (CRLF, a trailing empty column,
Ts only on row 1, estimation and validation side by side). Expected values are parsed from the files'
own text with the standard library, independently of the loaders. Skipped when the datasets are absent,
required when SYSID_REQUIRE_REALDATA=1."""

import csv

import numpy as np
import pytest
import yaml

from pipeline.config import load_config
from pipeline.data import Segment, load_record, make_split
from tests.seedcases import require_dataset

MODEL = {"states": ["y"], "inputs": ["u"], "params": {"a": 1.0, "b": 1.0}, "equations": {"y": "-a*y + b*u"}}


def _load(tmp_path, data):
    (tmp_path / "c.yaml").write_text(yaml.safe_dump({"name": "real", "data": data, "model": MODEL}))
    lc = load_config(tmp_path / "c.yaml")
    return lc, load_record(lc)


def _text_rows(path):
    """Rows of numbers of a whitespace-separated text file (blank lines skipped)."""
    with open(path, encoding="ascii", newline="") as fh:
        return [[float(v) for v in line.split()] for line in fh if line.strip()]


@pytest.mark.realdata
@pytest.mark.parametrize("rel,columns,n,timing", [
    ("daisy_heating_system/heating_system.dat", ["t", "u", "y"], 801, {"time": "t"}),
    ("daisy_dryer/dryer.dat", ["u", "y"], 1000, {"sample_time": 0.08}),
    ("daisy_ballbeam/ballbeam.dat", ["u", "y"], 1000, {"sample_time": 0.1}),
])
def test_daisy_tables_load_without_conversion(tmp_path, rel, columns, n, timing):
    path = require_dataset(rel)
    assert b"\r\n" in path.read_bytes()[:200]          # the files are CRLF, kept as they are
    _, rec = _load(tmp_path, {"path": str(path), "format": "table", "columns": columns, "inputs": ["u"],
                              "outputs": ["y"], **timing})
    rows = _text_rows(path)
    assert rec.n == n == len(rows)
    for i in (0, -1):
        got = [rec.inputs["u"][i], rec.outputs["y"][i]]
        want = rows[i][columns.index("u")], rows[i][columns.index("y")]
        assert got == list(want)
        if "time" in timing:
            assert rec.t[i] == rows[i][0]
    if rel.startswith("daisy_heating"):
        assert rec.dt == 2.0 and rec.t[-1] == 1600.0


@pytest.mark.realdata
def test_cascaded_tanks_loads_as_two_segments_of_1024(tmp_path):
    path = require_dataset("cascaded_tanks/dataBenchmark.csv")
    lc, rec = _load(tmp_path, {"path": str(path), "sample_time": 4, "inputs": {"uEst": "u"}, "outputs": {"yEst": "y"},
                               "validation": {"inputs": {"uVal": "u"}, "outputs": {"yVal": "y"}}})
    with open(path, encoding="ascii", newline="") as fh:
        table = [r for r in csv.reader(fh) if r]
    header, body = table[0], table[1:]
    assert header[-1] == "" and len(body) == 1024
    col = {name: np.array([float(r[header.index(name)]) for r in body]) for name in ("uEst", "uVal", "yEst", "yVal")}
    assert rec.segments == [Segment("estimation", 0, 1024, "estimation"), Segment("validation", 1024, 2048, "validation")]
    assert rec.dt == 4.0 and rec.t[1023] == rec.t[2047] == 4092.0 and rec.t[1024] == 0.0
    np.testing.assert_array_equal(rec.inputs["u"], np.concatenate([col["uEst"], col["uVal"]]))
    np.testing.assert_array_equal(rec.outputs["y"], np.concatenate([col["yEst"], col["yVal"]]))
    assert (rec.outputs["y"][0], rec.outputs["y"][2047]) == (5.205, 3.7179)   # first and last rows of the text
    split = make_split(lc, rec)
    assert (split.est, split.val) == ((0, 1024), (1024, 2048))
