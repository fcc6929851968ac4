"""MLflow round trip on a real sqlite store, read back with mlflow.search_runs."""

import json
from pathlib import Path

import pytest

from pipeline.cli import main

mlflow = pytest.importorskip("mlflow")


def test_mlflow_round_trip_on_sqlite(batch_runs, tmp_path, capsys):
    from mlflow.tracking import MlflowClient

    from pipeline.tracking.mlflow_backend import log_run
    uri = f"sqlite:///{tmp_path}/db/mlruns.db"
    run = next(r for r in batch_runs["results"] if r.ok and r.run_id.startswith("demo-"))
    folder = Path(run.path)
    s = json.loads((folder / "summary.json").read_text())
    rid = log_run(folder, uri)
    assert log_run(folder, uri) == rid                      # logging the same folder again is a no-op
    mlflow.set_tracking_uri(uri)
    df = mlflow.search_runs(experiment_names=["sysid"])
    assert len(df) == 1
    row = df.iloc[0]
    assert row["run_id"] == rid and row["tags.mlflow.runName"] == s["run_id"]
    assert row["tags.verdict"] == "discrepancy" and row["tags.main_cause"] == "cubic_stiffness"
    assert row["params.seed"] == "0" and row["params.model.equations.v"] == "(u - c*v - k*x)/m"
    assert row["metrics.final.validation.fit_percent"] == pytest.approx(s["final"]["validation"]["fit_percent"])
    assert row["metrics.nominal.params.k"] == pytest.approx(s["nominal"]["params"]["k"])
    # '+' is not allowed in MLflow keys: the extended model's metrics are logged under '_'
    assert "metrics.models.nominal_cubic_stiffness.bic" in df.columns
    arts = {a.path for a in MlflowClient(tracking_uri=uri).list_artifacts(rid)}
    assert {"summary.json", "manifest.json", "metrics.json", "params.yaml"} <= arts
    # the CLI logs another run folder into the same store
    other = next(r for r in batch_runs["results"] if r.ok and r.run_id.startswith("demo_b"))
    assert main(["track", other.path, "--uri", uri]) == 0
    assert "MLflow run" in capsys.readouterr().out
    df = mlflow.search_runs(experiment_names=["sysid"], filter_string="params.name = 'demo_b'")
    assert len(df) == 1 and df.iloc[0]["params.diagnose.alpha"] == "0.05"


def test_an_unreachable_tracking_server_fails_at_once(batch_runs, tmp_path, capsys):
    """MLflow's client retries a refused connection for about 4 minutes (its backoff is meant for a server
    that rate-limits): an independent probe waited 247 s for exit 2. A server that does not accept a TCP
    connection is exit 2 within the connect timeout, for ``track`` and before the analysis of ``report
    --track``; nothing is written."""
    import socket
    import time
    with socket.socket() as s:           # a port with nobody listening: bind, then close
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    uri = f"http://127.0.0.1:{port}"
    run = next(r for r in batch_runs["results"] if r.ok)
    t0 = time.monotonic()
    assert main(["track", run.path, "--uri", uri]) == 2
    err = capsys.readouterr().err
    assert time.monotonic() - t0 < 30
    assert err.startswith(f"error: --uri: cannot reach the tracking server 127.0.0.1:{port}") and err.count("\n") == 1
    cfg = Path(__file__).resolve().parents[2] / "configs" / "demo.yaml"
    out = tmp_path / "r"
    assert main(["report", str(cfg), "--out", str(out), "--track", uri]) == 2
    assert "error: --track: cannot reach the tracking server" in capsys.readouterr().err
    assert not out.exists()


def test_track_logs_nothing_when_one_folder_is_broken(batch_runs, tmp_path, capsys):
    """``track A B`` with B a hand-broken run folder logged A and then failed (an independent probe):
    every folder is read before any is logged, so the store is left as it was."""
    import shutil
    good = next(r for r in batch_runs["results"] if r.ok)
    broken = tmp_path / "broken"
    shutil.copytree(good.path, broken)
    text = (broken / "summary.json").read_text()
    (broken / "summary.json").write_text(text[: len(text) // 2])
    db = tmp_path / "db" / "ml.db"
    assert main(["track", good.path, str(broken), "--uri", f"sqlite:///{db}"]) == 2
    err = capsys.readouterr().err
    assert str(broken) in err and err.count("\n") == 1
    if db.exists():
        mlflow.set_tracking_uri(f"sqlite:///{db}")
        exp = mlflow.get_experiment_by_name("sysid")
        assert exp is None or len(mlflow.search_runs(experiment_ids=[exp.experiment_id])) == 0
