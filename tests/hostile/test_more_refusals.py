"""Bad input found by an independent probe (2026-12-04) that gave tracebacks, hung or wrote where it
should not. Each case: exit 2, one line naming the key or file, nothing written."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from pipeline.cli import main
from pipeline.diagnostics.stats import andrews_bandwidth
from pipeline.errors import EstimationError
from pipeline.estimators.bayes import GaussianPrior

ROOT = Path(__file__).resolve().parents[2]


def _cli(capsys, *args) -> tuple[int, str]:
    rc = main([str(a) for a in args])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if not ln.startswith("[")]
    assert "Traceback" not in err
    if rc == 2:
        assert len(lines) == 1 and lines[0].startswith("error: "), err
    return rc, err


def _demo(tmp_path: Path, **edit) -> Path:
    cfg = yaml.safe_load((ROOT / "configs" / "demo.yaml").read_text())
    cfg["data"]["path"] = str(tmp_path / "d.csv")
    cfg["diagnose"] = {"families": ["offset"], "max_findings": 1}
    cfg.update(edit)
    df = pd.read_csv(ROOT / "data" / "demo.csv").iloc[:600]
    df.to_csv(tmp_path / "d.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    return tmp_path / "c.yaml"


def test_a_csv_whose_first_data_row_is_short_names_the_missing_cells(tmp_path, capsys):
    c = _demo(tmp_path)
    lines = (tmp_path / "d.csv").read_text().splitlines()
    lines[1] = lines[1].split(",")[0]          # "t" only: pandas took the column count from this row
    (tmp_path / "d.csv").write_text("\n".join(lines) + "\n")
    rc, err = _cli(capsys, "diagnose", c, "--out", tmp_path / "o")
    assert rc == 2 and "NaN/inf value(s), first at row 0" in err and "empty or missing cell" in err
    assert not (tmp_path / "o").exists()


def test_a_csv_row_with_an_extra_field_is_refused_with_its_line(tmp_path, capsys):
    """A row with one field more than the header (a stray delimiter or value) was read with the extra
    field silently dropped: the other cells may then be shifted against their names."""
    c = _demo(tmp_path)
    lines = (tmp_path / "d.csv").read_text().splitlines()
    lines[50] += ",7.0"
    (tmp_path / "d.csv").write_text("\n".join(lines) + "\n")
    rc, err = _cli(capsys, "diagnose", c, "--out", tmp_path / "o")
    assert rc == 2 and "d.csv" in err and "Expected 3 fields in line 51, saw 4" in err, err
    assert not (tmp_path / "o").exists()


def test_a_declared_output_that_divides_by_zero_is_named(tmp_path, capsys):
    """The states simulate, the declared output x/z does not (z = 0): the message blamed "model.params,
    model.initial" and numpy printed two RuntimeWarnings; it now names model.outputs.y and where."""
    c = _demo(tmp_path)
    cfg = yaml.safe_load(c.read_text())
    cfg["model"]["params"]["z"] = 0.0
    cfg["model"]["outputs"] = {"y": "x/z"}
    cfg["data"]["outputs"] = {"x": "y"}
    c.write_text(yaml.safe_dump(cfg))
    rc, err = _cli(capsys, "diagnose", c, "--out", tmp_path / "o")
    assert rc == 2 and "model.outputs.y" in err and "x/z" in err and "t = 0 s" in err, err
    assert "RuntimeWarning" not in err and not (tmp_path / "o").exists()


@pytest.mark.parametrize("scale, ok", [(1e60, True), (1e100, False), (1e300, False)])
def test_huge_outputs_run_or_are_refused_with_the_column_named(tmp_path, capsys, scale, ok):
    c = _demo(tmp_path)
    df = pd.read_csv(tmp_path / "d.csv")
    df["x"] = df["x"] / df["x"].abs().max() * scale
    df.to_csv(tmp_path / "d.csv", index=False)
    rc, err = _cli(capsys, "diagnose", c, "--out", tmp_path / "o")
    if ok:
        assert rc == 0, err          # an OverflowError in the HAC bandwidth at 1e50
    else:
        assert rc == 2 and "column 'x' holds values up to" in err and "rescale" in err


def test_andrews_bandwidth_does_not_depend_on_a_common_scale():
    g = np.random.default_rng(0).standard_normal((500, 2)).cumsum(axis=0) * 0.1
    assert andrews_bandwidth(g) == andrews_bandwidth(g * 1e60) == andrews_bandwidth(g * 1e120) > 0


def test_a_prior_list_of_the_wrong_length_is_an_estimation_error_not_a_crash():
    with pytest.raises(EstimationError, match="prior mean: 9 values for 2 parameters"):
        GaussianPrior(list(range(9)), 1.0).arrays(2)
    m, c = GaussianPrior([1.0, 2.0], [4.0, 9.0]).arrays(2)
    assert m.tolist() == [1.0, 2.0] and np.diag(c).tolist() == [4.0, 9.0]


def test_batch_root_must_be_a_folder_on_a_real_filesystem(tmp_path, capsys):
    c = _demo(tmp_path)
    (tmp_path / "afile").write_text("x")
    rc, err = _cli(capsys, "batch", "--jobs", "1", "--root", tmp_path / "afile", c)
    assert rc == 2 and "--root" in err and "not a folder" in err
    rc, err = _cli(capsys, "batch", "--jobs", "1", "--root", "/proc/sysid-x", c)
    assert rc == 2 and "--root" in err and "/proc" in err


def test_runs_with_a_missing_root_says_so(tmp_path, capsys):
    rc, err = _cli(capsys, "runs", "--root", tmp_path / "nope")
    assert rc == 2 and "no such folder" in err


def test_a_run_folder_with_a_foreign_summary_layout_is_skipped_not_a_crash(tmp_path, capsys):
    c = _demo(tmp_path)
    (tmp_path / "runs").mkdir()
    assert _cli(capsys, "diagnose", c, "--out", tmp_path / "runs" / "r")[0] == 0
    run = tmp_path / "runs" / "r"
    s = json.loads((run / "summary.json").read_text())
    s["diagnosis"]["findings"] = ["x"]
    (run / "summary.json").write_text(json.dumps(s))
    (run / ".sysid-run").unlink()      # a marker-less folder (a legacy run's layout), its summary edited
    (run / "simulation.csv").unlink()  # (legacy runs had no simulated series)
    assert main(["runs", "--root", str(tmp_path / "runs")]) == 0
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err and "no runs" in captured.out
    assert "skipped" in captured.err and "diagnosis.findings is not a list of objects" in captured.err
    rc, err = _cli(capsys, "compare", run, run)
    assert rc == 2 and "layout" in err


@pytest.mark.parametrize("uri, needle", [("bogus://x", "unknown tracking URI scheme 'bogus'"),
                                         ("sqlite:////proc/sysid-x.db", "/proc")])
def test_a_bad_tracking_uri_is_refused_before_the_analysis(tmp_path, capsys, uri, needle):
    pytest.importorskip("mlflow")
    c = _demo(tmp_path)
    rc, err = _cli(capsys, "report", c, "--out", tmp_path / "o", "--track", uri)
    assert rc == 2 and "--track" in err and needle in err
    assert not (tmp_path / "o").exists()     # before: the run folder was written, then MLflow crashed


def test_grade_results_on_a_pseudo_filesystem_are_refused_before_grading(tmp_path, capsys):
    rc, err = _cli(capsys, "grade", "--key", tmp_path / "nokey.json", "--submissions", tmp_path,
                   "--out", "/proc/sysid-gradebook.csv")
    assert rc == 2 and "--out" in err and "/proc" in err
    rc, err = _cli(capsys, "grade", "--key", tmp_path / "nokey.json", "--submissions", tmp_path, "--jobs", "0")
    assert rc == 2 and "--jobs" in err
