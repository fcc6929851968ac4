"""Bad input: each broken config or record gives exit code 2, one message naming the file and the
key/column and what was expected, and no run folder (not even a half-written one)."""

import numpy as np
import pandas as pd
import pytest
import yaml

from pipeline.cli import main

GOOD = {
    "name": "bad", "seed": 0,
    "data": {"path": "rec.csv", "time": "t", "inputs": ["u"], "outputs": ["x"]},
    "model": {"states": ["x", "v"], "inputs": ["u"], "params": {"m": 1.0, "c": 0.6, "k": 4.0},
              "free": ["c", "k"], "equations": {"x": "v", "v": "(u - c*v - k*x)/m"}},
}


def _record(n=400, dt=0.02):
    rng = np.random.default_rng(0)
    t = np.arange(n) * dt
    return pd.DataFrame({"t": t, "u": rng.standard_normal(n), "x": rng.standard_normal(n)})


def _set(cfg, dotted, value):
    d = cfg
    keys = dotted.split(".")
    for k in keys[:-1]:
        d = d[k]
    if value is _DEL:
        del d[keys[-1]]
    else:
        d[keys[-1]] = value


_DEL = object()

CONFIG_CASES = {
    "unknown_key": (("model.equation", {"x": "v"}), "model.equation: unknown key"),
    "wrong_type": (("seed", "abc"), "seed"),
    "missing_required": (("data.outputs", _DEL), "data.outputs: required key is missing"),
    "unknown_name_in_expression": (("model.equations.v", "(u - c*v - q*x)/m"), "model.equations.v"),
    "attribute_access": (("model.equations.v", "x.__class__"), "model.equations.v"),
    "call_of_other_name": (("model.equations.v", "eval('1')"), "eval"),
    "free_not_in_params": (("model.free", ["c", "zeta"]), "free parameter 'zeta'"),
    "output_not_a_state": (("data.outputs", {"x": "position"}), "neither a state nor a declared output"),
    "equation_missing": (("model.equations", {"x": "v"}), "no equation for state 'v'"),
    "time_and_sample_time": (("data.sample_time", 0.02), "data.time or data.sample_time, not both"),
    "bad_intersample": (("data.intersample", "cubic"), "data.intersample"),
    "unknown_family": (("diagnose", {"families": ["cubic_stiffnes"]}), "unknown family 'cubic_stiffnes'"),
    "family_twice": (("diagnose", {"families": ["offset", "offset"]}), "family 'offset' is listed twice"),
    "number_too_large": (("model.params.k", "1e400"), "model.params.k: expected a finite number"),
    "overlapping_split": (("split", {"estimation": [0, 300], "validation": [200, None]}), "overlap"),
    "state_named_like_function": (("model.states", ["sin", "v"]), "reserved"),
    "input_without_column": (("data.inputs", []), "model input 'u' has no data column"),
    # the key path only: no pydantic validator tags ("dict[str,union[...]]") between the keys
    "initial_not_a_number": (("model.initial", {"x": "foo", "v": 0.0}), "error: {cfg}: model.initial.x: expected a number"),
    # accepted before and ignored or clipped (an independent probe, 2026-12-04)
    "units_unknown_signal": (("units", {"zz": "m"}), "units.zz: 'zz' is not a signal of this config"),
    "split_past_the_end": (("split", {"estimation": [0, 200], "validation": [200, 99999]}),
                           "split.validation: range [200, 99999) ends past the record's 400 samples"),
    "input_delay_longer_than_record": (("model.input_delay", 1e6), "model.input_delay: 1e+06 s is not shorter"),
    # cut silently to what was there before (an independent probe, 2026-12-07)
    "warmup_longer_than_the_room": (("split", {"estimation": [100, 300], "validation": [300, None], "warmup": 500}),
                                    "split.warmup: 500 samples of warm-up, but the estimation part starts 100 "
                                    "samples after the start of the record; at most 100"),
    "warmup_with_estimation_at_the_start": (("split", {"validation_fraction": 0.3, "warmup": 10**9}),
                                            "nothing to simulate before it: remove split.warmup"),
    "ml_uniform_bounds_reversed": (("estimators", [{"ml": {"density": "uniform", "low": 1.0, "high": 0.0}}]),
                                   "low (1) must be below high (0)"),
    "prefilter_unknown_param": (("prefilter", [{"name": "remove_mean", "params": {"foo": True}}]),
                                "prefilter[0]: remove_mean has no parameter 'foo'"),
    "prefilter_missing_param": (("prefilter", [{"name": "lowpass", "params": {}}]),
                                "prefilter[0]: lowpass needs params cutoff"),
    "prefilter_bool_for_number": (("prefilter", [{"name": "notch", "params": {"omega0": True}}]),
                                  "prefilter[0]: omega0: expected a positive number, got True"),
    # a comment character cuts each line at its first occurrence: a digit cut the numbers apart
    "comment_digit": (("data.comment", "0"), "data.comment: '0' can be part of a number"),
    # the estimation record again as validation record: every validation number in-sample (a probe, 2026-12-07)
    "validation_is_the_estimation_record": (("data.validation", {"path": "rec.csv"}),
                                            "error: {cfg}: data.validation: the validation record rec.csv holds "
                                            "the same samples as the estimation record rec.csv (data)"),
    # ignored with exit 0 (a probe, 2026-12-07): estimators fit the structures section's candidates
    "estimators_without_structures": (("estimators", ["ls", "iv"]),
                                      "estimators: the estimators fit the candidate structures of a structures section"),
    # a leading "." made a hidden run folder that readers skip and a later run's cleanup could take
    "hidden_name": (("name", ".a.tmp-999999"), "name: expected letters, digits"),
    # a degree of 10**6 hung; unknown keys of poly were accepted
    "poly_degree_huge": (("structures", {"equation": "v", "known": "u", "library": {"poly": {"vars": ["x"],
                          "degree": 1000000}}}), "structures.library.poly.degree"),
    "poly_unknown_key": (("structures", {"equation": "v", "known": "u", "library": {"poly": {"vars": ["x"],
                          "bogus": 1}}}), "structures.library.poly.bogus: unknown key"),
    # accepted with exit 0 and the fraction silently ignored (an audit, 2026-12-07: D4)
    "split_ranges_and_fraction": (("split", {"estimation": [0, 300], "validation": [300, None],
                                             "validation_fraction": 0.3}),
                                  "error: {cfg}: split.validation_fraction: 0.3 given beside the explicit ranges "
                                  "split.estimation [0, 300] and split.validation [300, null], which decide the "
                                  "split (the fraction would be ignored); expected either the ranges or "
                                  "validation_fraction, not both"),
    # one column fed as the input and scored as the output: a nonsense run with exit 0 (an audit: D8)
    "same_column_input_and_output": (("data.inputs", {"x": "u"}),
                                     "error: {cfg}: data.inputs: column 'x' is both an input (data.inputs: x -> u) "
                                     "and a measured output (data.outputs: x -> x)"),
    "same_column_in_the_validation_record": (("data.validation", {"path": "rec.csv", "inputs": {"x": "u"}}),
                                             "error: {cfg}: data.validation.inputs: column 'x' is both an input "
                                             "(data.validation.inputs: x -> u) and a measured output "
                                             "(data.outputs: x -> x)"),
    "same_column_in_an_experiment": (("data.experiments", [{"role": "estimation"},
                                                           {"role": "validation", "outputs": {"u": "x"}}]),
                                     "error: {cfg}: data.inputs: column 'u' is both an input (data.inputs: u -> u) "
                                     "and a measured output (data.experiments[1].outputs: u -> x)"),
    # the time column mapped as an input too: the time axis would drive the model (noticed by the audit)
    "time_column_as_input": (("data.inputs", {"t": "u"}),
                             "error: {cfg}: data.time: column 't' is the time axis (data.time) and also an input "
                             "(data.inputs)"),
    "time_column_as_an_experiments_output": (("data.experiments", [{"role": "estimation"},
                                                                   {"role": "validation", "outputs": {"t": "x"}}]),
                                             "error: {cfg}: data.time: column 't' is the time axis (data.time) "
                                             "and also a measured output (data.experiments[1].outputs)"),
    # signals: [] was read as every signal, without a word (noticed by the audit)
    "empty_signals": (("prefilter", [{"name": "remove_mean", "signals": []}]),
                      "error: {cfg}: prefilter[0].signals: an empty list; expected the signals the step applies to"),
    # signals: [x] on a decimate step was ignored: u was decimated too, without a word (an audit: D9)
    "decimate_with_signals": (("prefilter", [{"name": "decimate", "params": {"q": 2}, "signals": ["x"]}]),
                              "error: {cfg}: prefilter[0].signals: decimate changes the sample time of the whole "
                              "record, so it applies to every input and output together; expected no signals"),
}


def test_yaml_aliases_are_refused_before_they_expand(tmp_path, capsys):
    """Nine levels of nine aliases: a few hundred bytes that expand to 9**9 nodes (ran > 120 s)."""
    lines = ['a: &a ["x","x","x","x","x","x","x","x","x"]']
    for i, (p, q) in enumerate(zip("abcdefgh", "bcdefghi")):
        lines.append(f"{q}: &{q} [" + ",".join(f"*{p}" for _ in range(9)) + "]")
    (tmp_path / "c.yaml").write_text("\n".join(lines) + "\n" + yaml.safe_dump(GOOD))
    _record().to_csv(tmp_path / "rec.csv", index=False)
    _expect_exit2(tmp_path, capsys, "aliases (and anchors &name) are not supported")


@pytest.mark.parametrize("case", list(CONFIG_CASES))
def test_bad_config(tmp_path, capsys, case):
    (path_value, expected) = CONFIG_CASES[case]
    cfg = yaml.safe_load(yaml.safe_dump(GOOD))
    _set(cfg, *path_value)
    _record().to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    _expect_exit2(tmp_path, capsys, expected.replace("{cfg}", str(tmp_path / "c.yaml")))


def _expect_exit2(tmp_path, capsys, expected, config="c.yaml"):
    out = tmp_path / "runs" / "r"
    out.parent.mkdir(exist_ok=True)  # a user-given --out needs an existing parent (runfolder.check_target)
    code = main(["report", str(tmp_path / config), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2, err
    assert expected in err, err
    lines = [ln for ln in err.splitlines() if not ln.startswith("[")]  # progress lines aside
    assert len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err
    assert not out.exists()
    assert not any((tmp_path / "runs").iterdir())  # not even a hidden temp folder


def _broken_record(kind):
    df = _record()
    if kind == "nan":
        df.loc[57, "x"] = np.nan
    elif kind == "time_not_increasing":
        df.loc[100, "t"] = df.loc[99, "t"]
    elif kind == "nonuniform":
        df.loc[200:, "t"] += 0.005
    elif kind == "too_few":
        df = df.iloc[:20]
    elif kind == "constant_input":
        df["u"] = 1.5
    elif kind == "constant_output":
        df["x"] = 100.0
    elif kind == "missing_column":
        df = df.drop(columns=["x"])
    elif kind == "non_numeric":
        df["u"] = df["u"].astype(object)
        df.loc[12, "u"] = "n/a?"
    elif kind == "inf":
        df.loc[3, "u"] = np.inf
    elif kind == "tiny_output":
        df["x"] *= 1e-160
    elif kind == "tiny_input_and_output":
        df["u"] *= 1e-300
        df["x"] *= 1e-300
    return df


RECORD_CASES = {
    "nan": "column 'x' has 1 NaN/inf value(s), first at row 57",
    "inf": "column 'u' has 1 NaN/inf value(s), first at row 3",
    "time_not_increasing": "not strictly increasing at row 100",
    "nonuniform": "non-uniform sampling",
    "too_few": "only 20 samples",
    "constant_input": "input 'u' is constant (1.5); a constant input excites nothing: write its value into the "
                      "equations in place of the input, or add a record that moves it (data.experiments)",
    "constant_output": "output 'x' is constant",     # used to end in an internal error (log of a zero residual)
    "missing_column": "column 'x' (output) not found",
    "non_numeric": "non-numeric value 'n/a?' at row 12",
    # an independent probe (2026-12-07): squares of 1e-160 underflow to 0, which ended in internal errors
    # (a NaN Jacobian, "SVD did not converge", log(0) in the BIC) or, for 1e-300, in a NaN fit % and findings
    "tiny_output": "column 'x' holds values no larger than",
    "tiny_input_and_output": "column 'u' holds values no larger than",
}


@pytest.mark.parametrize("case", list(RECORD_CASES))
def test_bad_record(tmp_path, capsys, case):
    _broken_record(case).to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(GOOD))
    _expect_exit2(tmp_path, capsys, RECORD_CASES[case])


def test_nonuniform_message_says_by_how_much(tmp_path, capsys):
    _broken_record("nonuniform").to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(GOOD))
    _expect_exit2(tmp_path, capsys, "(25 % off; data.max_jitter allows 1 %)")


def test_messages_name_the_file(tmp_path, capsys):
    _broken_record("nan").to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(GOOD))
    _expect_exit2(tmp_path, capsys, str(tmp_path / "rec.csv"))
    cfg = yaml.safe_load(yaml.safe_dump(GOOD))
    cfg["model"]["free"] = ["zeta"]
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    _expect_exit2(tmp_path, capsys, f"{tmp_path / 'c.yaml'}: model.free:")


@pytest.mark.parametrize("content,expected", [
    (None, "config file not found"),
    ("name: [unclosed", "not valid YAML"),
    ("- a\n- b\n", "expected a YAML mapping"),
])
def test_unreadable_config(tmp_path, capsys, content, expected):
    if content is not None:
        (tmp_path / "c.yaml").write_text(content)
    _expect_exit2(tmp_path, capsys, expected)


def test_missing_data_file_and_unknown_format(tmp_path, capsys):
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(GOOD))
    _expect_exit2(tmp_path, capsys, "data file not found")
    cfg = yaml.safe_load(yaml.safe_dump(GOOD))
    cfg["data"]["path"] = "rec.xlsx"
    (tmp_path / "rec.xlsx").write_text("x")
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    _expect_exit2(tmp_path, capsys, "unknown data format '.xlsx'")
    cfg["data"]["path"] = "rec.parquet"
    (tmp_path / "rec.parquet").write_bytes(b"not parquet")
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    _expect_exit2(tmp_path, capsys, "cannot read as parquet")


def test_model_that_diverges_is_bad_input(tmp_path, capsys):
    cfg = yaml.safe_load(yaml.safe_dump(GOOD))
    cfg["model"]["equations"]["v"] = "(u + c*v + k*x)/m"  # wrong signs: unstable
    cfg["model"]["params"]["c"] = 5.0
    _record(n=2000).to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    _expect_exit2(tmp_path, capsys, f"{tmp_path / 'c.yaml'}: model: the model diverges")


@pytest.mark.parametrize("equation, value", [("(u - c*v - k*x)/x", "inf"), ("(u - c*v - k*x)/m + sqrt(x - 5)", "nan")])
def test_an_equation_undefined_at_the_start_is_named(tmp_path, capsys, equation, value):
    """An independent probe: an equation undefined where the simulation starts (1/0 at x(0) = 0, sqrt of
    a negative number) was reported under the key ``model``. The key is the equation's, and the message
    says what it evaluates to and at which state and input."""
    cfg = yaml.safe_load(yaml.safe_dump(GOOD))
    cfg["model"]["equations"]["v"] = equation
    _record().to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    _expect_exit2(tmp_path, capsys, f"{tmp_path / 'c.yaml'}: model.equations.v: the model diverges")
    code = main(["report", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "runs" / "r2")])
    err = capsys.readouterr().err.replace("-inf", "inf")
    assert code == 2
    assert f"v' = {equation} is {value} at t = 0 s (x = 0, v = 0, u = " in err, err


def test_an_equation_undefined_inside_a_step_is_named_with_the_stage_state(tmp_path, capsys):
    """An auditor's ``k*sqrt(x)``: every sample's state is defined, but an RK4 stage of one step takes x
    below 0, and the error named only ``model``. The key is the equation's, and the message gives the
    stage's state, where x < 0."""
    import re
    cfg = yaml.safe_load(yaml.safe_dump(GOOD))
    cfg["model"]["equations"]["v"] = "(u - c*v - k*sqrt(x))/m"
    _record().to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    _expect_exit2(tmp_path, capsys, f"{tmp_path / 'c.yaml'}: model.equations.v: the model diverges")
    code = main(["report", str(tmp_path / "c.yaml"), "--out", str(tmp_path / "runs" / "r2")])
    err = capsys.readouterr().err
    assert code == 2 and "v' = (u - c*v - k*sqrt(x))/m is nan at an RK4 stage of the step to that sample" in err
    assert float(re.search(r"\(x = (-?[0-9.e+-]+),", err).group(1)) < 0


def test_a_copy_of_the_estimation_record_is_no_validation_record(tmp_path, capsys):
    """The same samples under another file name (a copy) are refused as the same file is: the check is on
    the samples read, so the validation numbers cannot be in-sample by renaming. A different record runs,
    and so does one file holding both records in different columns (tests/test_loaders.py)."""
    cfg = yaml.safe_load(yaml.safe_dump(GOOD))
    cfg["data"]["experiments"] = [{"path": "rec.csv", "role": "estimation"}, {"path": "other.csv", "role": "estimation"},
                                  {"path": "copy.csv", "role": "validation"}]
    _record().to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "copy.csv").write_bytes((tmp_path / "rec.csv").read_bytes())
    other = _record()
    other["x"] = other["x"] + 1.0
    other.to_csv(tmp_path / "other.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    _expect_exit2(tmp_path, capsys, "data.experiments[2]: the validation record copy.csv holds the same samples "
                                    "as the estimation record rec.csv (data.experiments[0])")
    from pipeline.config import load_config
    from pipeline.data import load_record
    cfg["data"]["experiments"][2]["path"] = "other.csv"
    cfg["data"]["experiments"][1]["path"] = "copy.csv"
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    rec = load_record(load_config(tmp_path / "c.yaml"))
    assert [g.role for g in rec.segments] == ["estimation", "estimation", "validation"]


def test_a_constant_column_is_named_by_its_column(tmp_path, capsys):
    """With data.outputs mapping a column to a model name, the message named only the model name
    (an independent probe: "output 'x2' is constant" for the file's column 'y2')."""
    cfg = yaml.safe_load(yaml.safe_dump(GOOD))
    cfg["data"]["outputs"] = {"pos": "x"}
    df = _record().rename(columns={"x": "pos"})
    df["pos"] = 0.25
    df.to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    _expect_exit2(tmp_path, capsys, "column 'pos' (output 'x') is constant (0.25)")


def test_numbers_with_an_exponent_are_numbers(tmp_path):
    """PyYAML (YAML 1.1) reads 1e5, 4e0 and 1.5e5 as strings (its float needs a dot and a signed
    exponent): `k: 4e0` was "expected a number, got str '4e0'". YAML 1.2 reads them as numbers."""
    from pipeline.config import load_config
    _record().to_csv(tmp_path / "rec.csv", index=False)
    text = yaml.safe_dump(GOOD).replace("k: 4.0", "k: 4e0").replace("c: 0.6", "c: 6E-1").replace("m: 1.0", "m: .1e1")
    assert "k: 4e0" in text and "c: 6E-1" in text and "m: .1e1" in text
    (tmp_path / "c.yaml").write_text(text)
    p = load_config(tmp_path / "c.yaml").cfg.model.params
    assert (p["k"], p["c"], p["m"]) == (4.0, 0.6, 1.0)


def test_a_fraction_left_at_its_default_is_not_refused_beside_ranges(tmp_path):
    """Only a validation_fraction the user wrote conflicts with split ranges or separate records: the
    default every config carries does not, and the config as extended.yaml writes it back
    (LoadedConfig.canonical without structures and estimators, pipeline.extended) loads and splits again,
    with the same run-id hash."""
    from pipeline.config import load_config
    from pipeline.data import load_record, make_split
    _record().to_csv(tmp_path / "rec.csv", index=False)
    other = _record()
    other["x"] = other["x"] + 1.0
    other.to_csv(tmp_path / "val.csv", index=False)
    for key, value in (("split", {"estimation": [0, 300], "validation": [300, None]}),
                       ("data.validation", {"path": "val.csv"})):
        cfg = yaml.safe_load(yaml.safe_dump(GOOD))
        _set(cfg, key, value)
        (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
        lc = load_config(tmp_path / "c.yaml")
        assert "validation_fraction" not in lc.canonical()["split"]
        back = {k: v for k, v in lc.canonical().items() if k not in ("structures", "estimators")}
        (tmp_path / "again.yaml").write_text(yaml.safe_dump(back))
        again = load_config(tmp_path / "again.yaml")
        assert again.sha256() == lc.sha256()
        assert make_split(again, load_record(again)) == make_split(lc, load_record(lc))


def test_the_resolved_config_of_every_shipped_config_loads_again_with_the_same_run_id(tmp_path):
    """config.resolved.yaml (LoadedConfig.canonical) put back beside the config it came from loads again
    and gives the same run id: the default estimators of a config without a structures section were
    written out and then refused ('estimators: ... add a structures section or remove estimators'), and
    the default validation_fraction beside split ranges or separate records would now be refused too."""
    from pathlib import Path

    from pipeline.config import load_config
    root = Path(__file__).resolve().parents[1] / "configs"
    for path in sorted(root.glob("*.yaml")):
        lc = load_config(path)
        back = path.parent / f".resolved-{path.stem}-{tmp_path.name}.yml"   # not matched by *.yaml
        try:
            back.write_text(yaml.safe_dump(lc.canonical(), sort_keys=False))
            assert load_config(back).sha256() == lc.sha256(), path.name
        finally:
            back.unlink(missing_ok=True)


def test_shipped_configs_still_load():
    from pathlib import Path

    from pipeline.config import load_config
    root = Path(__file__).resolve().parents[1] / "configs"
    paths = sorted(root.glob("*.yaml"))
    assert len(paths) >= 5
    for p in paths:
        load_config(p)


def test_apply_prefilters_refuses_signals_on_decimate(tmp_path):
    """The same refusal for a caller that builds the steps itself (no load_config): it used to decimate
    every signal whatever ``signals`` said."""
    from pipeline.config import PrefilterStepCfg, load_config
    from pipeline.data import apply_prefilters, load_record
    from pipeline.errors import ConfigError
    _record().to_csv(tmp_path / "rec.csv", index=False)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(GOOD))
    rec = load_record(load_config(tmp_path / "c.yaml"))
    n = rec.n
    with pytest.raises(ConfigError) as e:
        apply_prefilters(rec, [PrefilterStepCfg(name="decimate", params={"q": 2}, signals=["x"])], "c.yaml")
    assert str(e.value).startswith("c.yaml: prefilter[0].signals: decimate changes the sample time")
    assert rec.n == n
