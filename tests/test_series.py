"""``simulation.csv`` in the run folder (pipeline/series.py): columns, parts, agreement with
summary.json's free-run RMSE, byte-identical reruns, separate records, the CSV format."""

import io
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from pipeline.cli import main
from pipeline.runfolder import read_marker
from pipeline.series import SeriesTable, to_csv

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "configs" / "demo.yaml"      # mass-spring-damper with a hidden cubic stiffness: one finding


def _read(folder: Path) -> tuple[pd.DataFrame, dict]:
    return pd.read_csv(folder / "simulation.csv"), json.loads((folder / "summary.json").read_text())


def _rmse(d: pd.DataFrame, part: str, outputs: list[str], model: str) -> float:
    rows = d[d["part"] == part]
    r = np.column_stack([rows[y] - rows[f"{y}_{model}"] for y in outputs])
    return math.sqrt(float(np.mean(r ** 2)))


def _assert_rmse_matches_summary(d: pd.DataFrame, s: dict) -> None:
    outs = s["data"]["outputs"]
    for model in ("nominal", "final"):
        for part in ("estimation", "validation"):
            assert _rmse(d, part, outs, model) == pytest.approx(s[model][part]["rmse_sim"], rel=1e-8, abs=0), \
                (model, part)


def test_columns_and_parts_on_the_demo(demo_runs):
    d, s = _read(demo_runs[0])
    assert list(d.columns) == ["t", "part", "u", "x", "x_nominal", "x_final"]
    assert len(d) == s["data"]["n_samples"] == 3000
    (e0, e1), (v0, v1) = s["data"]["estimation"], s["data"]["validation"]
    assert (e0, e1, v0, v1) == (0, 2100, 2100, 3000)
    assert (d["part"][e0:e1] == "estimation").all() and (d["part"][v0:v1] == "validation").all()
    # the measured columns are the record's own samples (demo.csv has 10 significant digits: exact)
    raw = pd.read_csv(ROOT / "data" / "demo.csv")
    for c in ("t", "u", "x"):
        np.testing.assert_array_equal(d[c].to_numpy(), raw[c].to_numpy(), err_msg=c)
    assert np.isfinite(d[["x_nominal", "x_final"]].to_numpy()).all()
    # written in both commands, listed (with its sha256) in the run-folder marker
    for folder in demo_runs:
        files = read_marker(folder)["files"]
        assert files["simulation.csv"]["size"] == (folder / "simulation.csv").stat().st_size
    assert "<code>simulation.csv</code>" in (demo_runs[0] / "report.html").read_text()   # named, not linked


def test_rmse_from_the_csv_is_summary_rmse_sim(demo_runs):
    """Estimation and validation, nominal and final: the CSV holds the arrays summary.json's numbers
    come from (a final model with the accepted cubic stiffness, so nominal and final differ)."""
    d, s = _read(demo_runs[0])
    assert [f["family"] for f in s["diagnosis"]["findings"]][:1] == ["cubic_stiffness"]
    assert s["nominal"]["validation"]["rmse_sim"] > 5 * s["final"]["validation"]["rmse_sim"]
    assert not np.allclose(d["x_nominal"], d["x_final"])
    _assert_rmse_matches_summary(d, s)


def test_two_runs_write_byte_identical_series(demo_runs):
    a, b = (p / "simulation.csv" for p in demo_runs)
    raw = a.read_bytes()
    assert raw == b.read_bytes()
    assert b"\r" not in raw and raw.endswith(b"\n") and not raw.endswith(b"\n\n")


def test_unused_samples_between_the_parts(tmp_path):
    """Samples in neither range are rows labelled ``unused`` (row k stays sample k)."""
    cfg = yaml.safe_load(DEMO.read_text())
    cfg["data"]["path"] = str(ROOT / "data" / "demo.csv")
    cfg["split"] = {"estimation": [0, 2000], "validation": [2200, None]}
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["diagnose", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "run")]) == 0
    d, s = _read(tmp_path / "run")
    assert len(d) == 3000
    assert d["part"].value_counts().to_dict() == {"estimation": 2000, "validation": 800, "unused": 200}
    assert (d["part"][2000:2200] == "unused").all()
    _assert_rmse_matches_summary(d, s)


def test_separate_validation_record(tmp_path):
    """data.validation in its own file: rows of both records, a ``record`` column naming each, the
    time restarting with the validation record, and the RMSE still summary.json's."""
    raw = pd.read_csv(ROOT / "data" / "demo.csv")
    est, val = raw.iloc[:2100], raw.iloc[2100:].copy()
    val["t"] = val["t"] - val["t"].iloc[0]
    est.to_csv(tmp_path / "est.csv", index=False)
    val.to_csv(tmp_path / "val.csv", index=False)
    cfg = yaml.safe_load(DEMO.read_text())
    cfg["data"]["path"] = "est.csv"
    cfg["data"]["validation"] = {"path": "val.csv"}
    del cfg["split"]
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["diagnose", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "run")]) == 0
    d, s = _read(tmp_path / "run")
    assert list(d.columns) == ["t", "part", "record", "u", "x", "x_nominal", "x_final"]
    assert len(d) == 3000 and s["data"]["validation"] == [2100, 3000]
    assert d["record"].value_counts().to_dict() == {"estimation": 2100, "validation": 900}
    assert (d["part"][:2100] == "estimation").all() and (d["part"][2100:] == "validation").all()
    assert d["t"][2100] == 0.0 and d["t"][0] == 0.0
    np.testing.assert_array_equal(d["x"].to_numpy(), raw["x"].to_numpy())
    _assert_rmse_matches_summary(d, s)


def test_csv_format_numbers_nan_and_quoted_names():
    """%.10g numbers, ``nan`` for NaN, a record name with a comma or quote quoted; pandas' defaults
    read it back."""
    tab = SeriesTable(["t", "part", "record", "y"],
                      [np.array([0.0, 0.1]), np.array(["estimation", "validation"], dtype=object),
                       np.array(['run 1, "cold"', "plain"], dtype=object), np.array([1 / 3, np.nan])])
    raw = to_csv(tab)
    assert raw == b't,part,record,y\n0,estimation,"run 1, ""cold""",0.3333333333\n0.1,validation,plain,nan\n'
    d = pd.read_csv(io.BytesIO(raw))
    assert d["record"].tolist() == ['run 1, "cold"', "plain"] and math.isnan(d["y"][1])


def test_an_input_named_like_a_column_gets_its_role_appended(tmp_path):
    """An input called ``part`` (a plausible name for a feed) must not repeat the ``part`` header:
    pandas would read the input as ``part.1`` and a user's ``d["part"]`` would be the labels."""
    raw = pd.read_csv(ROOT / "data" / "demo.csv").rename(columns={"u": "part"})
    raw.to_csv(tmp_path / "d.csv", index=False)
    cfg = yaml.safe_load(DEMO.read_text())
    cfg["data"].update(path="d.csv", inputs=["part"])
    cfg["model"]["inputs"] = ["part"]
    cfg["model"]["equations"]["v"] = "(part - c*v - k*x)/m"
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    assert main(["diagnose", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "run")]) == 0
    header = (tmp_path / "run" / "simulation.csv").read_text().split("\n", 1)[0].split(",")
    assert header == ["t", "part", "part_input", "x", "x_nominal", "x_final"]
    d, s = _read(tmp_path / "run")
    np.testing.assert_allclose(d["part_input"].to_numpy(), raw["part"].to_numpy(), rtol=1e-9)
    assert set(d["part"]) == {"estimation", "validation"}
    _assert_rmse_matches_summary(d, s)
