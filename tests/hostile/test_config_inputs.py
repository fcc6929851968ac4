"""Hostile-input corpus, config side (issue 7): YAML, names, numbers, expressions, options and report
text. Each case runs the real CLI in a subprocess under the harness's time and memory bound and must
exit 2 with one ``error:`` line naming the file and the key, with no traceback and no run folder."""

from __future__ import annotations

import copy

import numpy as np
import pandas as pd
import pytest
import yaml

from .harness import assert_bad_input, run_cli, snapshot

GOOD = {
    "name": "hostile", "seed": 0,
    "data": {"path": "rec.csv", "time": "t", "inputs": ["u"], "outputs": ["x", "v"]},
    "model": {"states": ["x", "v"], "inputs": ["u"], "params": {"m": 1.0, "c": 0.6, "k": 4.0},
              "free": ["c", "k"], "equations": {"x": "v", "v": "(u - c*v - k*x)/m"}},
    "diagnose": {"families": ["offset"], "max_findings": 1},
}
STRUCT = {"equation": "x", "known": "0", "candidates": {"A": ["v"]}}


@pytest.fixture()
def folder(tmp_path):
    rng = np.random.default_rng(0)
    n = 300
    pd.DataFrame({"t": np.arange(n) * 0.02, "u": rng.normal(size=n), "x": rng.normal(size=n),
                  "v": rng.normal(size=n)}).to_csv(tmp_path / "rec.csv", index=False)
    return tmp_path


def _with(path_value_pairs):
    cfg = copy.deepcopy(GOOD)
    for dotted, value in path_value_pairs:
        d = cfg
        keys = dotted.split(".")
        for k in keys[:-1]:
            d = d.setdefault(k, {})
        d[keys[-1]] = value
    return cfg


def _check(folder, text: str, *mention: str):
    cfg = folder / "c.yaml"
    cfg.write_text(text)
    before = snapshot(folder)
    res = run_cli("diagnose", str(cfg), "--out", str(folder / "run"))
    assert_bad_input(res, str(cfg), *mention)
    assert snapshot(folder) == before
    assert sorted(p.name for p in folder.iterdir()) == ["c.yaml", "rec.csv"]


# (id, config text or a list of overrides, strings the message must contain)
CASES = [
    # YAML
    ("duplicate-key", yaml.safe_dump(GOOD).replace("seed: 0", "seed: 0\nseed: 1"), ["duplicate key 'seed'"]),
    ("yaml-1.1-off-key", yaml.safe_dump(GOOD) + "off: 3\n", ["off", "unknown key"]),
    ("yes-is-not-a-bool", [("data.remove_mean", "yes")], ["data.remove_mean"]),
    ("deep-nesting", "name: x\nseed: 0\nextra: " + "[" * 5000 + "]" * 5000 + "\n", ["nested too deeply"]),
    ("deep-mapping", "a:\n" + "".join("  " * i + "b:\n" for i in range(1, 200)) + "  " * 200 + "c: 1\n",
     ["nested too deeply"]),
    ("not-a-mapping", "- 1\n- 2\n", ["mapping"]),
    ("binary", "\x00\x01\x02" * 10, []),
    ("non-string-key", yaml.safe_dump(GOOD) + "1: 2\n", ["keys must be text"]),
    ("tab-syntax", "name: x\n\tseed: 0\n", ["not valid YAML"]),
    # names
    ("keyword-param", [("model.params", {"lambda": 1.0, "c": 0.6, "k": 4.0, "m": 1.0})], ["lambda", "reserved"]),
    ("nfkc-twin", [("model.params", {"m": 1.0, "c": 0.6, "k": 4.0, "ｋ": 1.0})], ["model.params", "NFKC"]),
    ("np-shadow", [("model.params", {"ｎｐ": 1.0, "c": 0.6, "k": 4.0, "m": 1.0})], ["model.params"]),
    ("np-name", [("model.params", {"np": 1.0, "c": 0.6, "k": 4.0, "m": 1.0})], ["reserved"]),
    ("builtin-name", [("model.states", ["x", "max"]), ("model.equations", {"x": "max", "max": "u"})],
     ["model.states", "reserved"]),
    ("generated-name", [("model.states", ["x", "xs"]), ("model.equations", {"x": "xs", "xs": "u"})], ["reserved"]),
    ("underscore-name", [("model.params", {"_m": 1.0, "c": 0.6, "k": 4.0, "m": 1.0})], ["reserved"]),
    ("pi-as-param", [("model.params", {"pi": 3.0, "c": 0.6, "k": 4.0, "m": 1.0})], ["reserved"]),
    ("duplicate-free", [("model.free", ["c", "c"])], ["model.free", "twice"]),
    ("too-many-states", [("model.states", [f"s{i}" for i in range(2000)]),
                         ("model.equations", {f"s{i}": "u" for i in range(2000)})], ["model.states", "at most"]),
    # numbers
    ("bool-as-number", [("model.params.m", True)], ["model.params.m", "number"]),
    ("bool-seed", [("seed", True)], ["seed"]),
    ("negative-seed", [("seed", -1)], ["seed"]),
    ("huge-seed", [("seed", 2 ** 32)], ["seed"]),
    ("infinite-param", [("model.params.m", float("inf"))], ["model.params.m", "finite"]),
    ("nan-param", [("model.params.c", float("nan"))], ["model.params.c", "finite"]),
    ("string-number", [("model.params.k", "four")], ["model.params.k"]),
    ("inf-sample-time", [("data.time", None), ("data.sample_time", float("inf"))], ["data.sample_time"]),
    ("validation-fraction-0.99", [("split.validation_fraction", 0.99)], ["validation_fraction"]),
    ("validation-fraction-1", [("split.validation_fraction", 1.0)], ["split.validation_fraction"]),
    ("float-substeps", [("model.substeps", 2.5)], ["model.substeps"]),
    ("bool-alpha", [("diagnose.alpha", True)], ["diagnose.alpha"]),
    # expressions
    ("flat-sum-ok-but-unknown", [("model.equations.v", " + ".join(f"q{i}" for i in range(300)))], ["unknown name"]),
    ("deep-expression", [("model.equations.v", "u*(" * 1000 + "x" + ")" * 1000)], ["model.equations.v"]),
    ("1e999", [("model.equations.v", "1e999*x + u")], ["model.equations.v", "too large"]),
    ("400-digit", [("model.equations.v", "1" + "0" * 400 + "*x + u")], ["model.equations.v", "too large"]),
    ("constant-div-zero", [("model.equations.v", "u - k*x + 1/0")], ["model.equations.v", "not a finite"]),
    ("candidate-div-zero", [("structures", {**STRUCT, "candidates": {"A": ["1/0"]}})],
     ["structures.candidates.A[0]", "not a finite"]),
    ("dunder", [("model.equations.v", "__import__('os').system('true')")], ["model.equations.v"]),
    ("attribute", [("model.equations.v", "u.real")], ["model.equations.v"]),
    ("lambda-expr", [("model.equations.v", "(lambda: 1)()")], ["model.equations.v"]),
    ("string-expr", [("model.equations.v", "'a' * 3")], ["model.equations.v"]),
    ("comparison", [("model.equations.v", "u if x > 0 else v")], ["model.equations.v"]),
    ("huge-text", [("model.equations.v", "u" + " " * 30000)], ["model.equations.v", "characters"]),
    ("empty-expr", [("model.equations.v", "  ")], ["model.equations.v", "empty"]),
    ("list-expr", [("model.equations.v", ["u"])], ["model.equations.v"]),
    # options
    ("rls-lam-text", [("structures", STRUCT), ("estimators", [{"rls": {"lam": "abc"}}])], ["estimators[0].rls.lam"]),
    ("mcmc-nsteps-1e9", [("structures", STRUCT), ("estimators", [{"mcmc": {"nsteps": 1e9}}])],
     ["estimators[0].mcmc.nsteps"]),
    ("mcmc-nwalkers-1e6", [("structures", STRUCT), ("estimators", [{"mcmc": {"nwalkers": 1e6}}])],
     ["estimators[0].mcmc.nwalkers"]),
    ("mcmc-chain-too-big", [("structures", STRUCT), ("estimators", [{"mcmc": {"nwalkers": 1000, "nsteps": 100000}}])],
     ["estimators[0].mcmc", "at most"]),
    ("wls-bool-text", [("structures", STRUCT), ("estimators", [{"wls": {"fgls": "yes"}}])], ["estimators[0].wls.fgls"]),
    ("unknown-option", [("structures", STRUCT), ("estimators", [{"ls": {"foo": 1}}])], ["estimators[0].ls.foo"]),
    ("ml-density", [("structures", STRUCT), ("estimators", [{"ml": {"density": "cauchy"}}])],
     ["estimators[0].ml.density"]),
    ("verdict-as-family", [("diagnose.families", ["none"])], ["diagnose.families", "unknown family"]),
    ("unknown-family", [("diagnose.families", ["gremlins"])], ["diagnose.families", "unknown family"]),
    ("rules-zero", [("structures", {**STRUCT, "takagi_sugeno": {"rules": [0]}})], ["structures.takagi_sugeno.rules"]),
    # parameter bounds
    ("bound-not-free", [("model.bounds", {"m": [0, None]})], ["model.bounds.m", "not a free parameter"]),
    ("bound-unknown", [("model.bounds", {"zeta": [0, 1]})], ["model.bounds.zeta", "not a free parameter"]),
    ("bound-reversed", [("model.bounds", {"c": [2, 1]})], ["model.bounds.c", "not below"]),
    ("bound-equal", [("model.bounds", {"c": [1, 1]})], ["model.bounds.c", "not below"]),
    ("bound-start-outside", [("model.bounds", {"k": [5, None]})], ["model.bounds.k", "k = 4", "outside"]),
    ("bound-text", [("model.bounds", {"c": ["zero", 1]})], ["model.bounds.c"]),
    ("bound-one-number", [("model.bounds", {"c": 0})], ["model.bounds.c"]),
    ("bound-three-numbers", [("model.bounds", {"c": [0, 1, 2]})], ["model.bounds.c"]),
    ("bound-inf", [("model.bounds", {"c": [0, ".inf"]})], ["model.bounds.c"]),
    # accepted with exit 0 and ignored or nonsense (an audit, 2026-12-07: D4, D8, D9)
    ("split-ranges-and-fraction", [("split", {"estimation": [0, 200], "validation": [200, None],
                                              "validation_fraction": 0.3})],
     ["split.validation_fraction", "explicit ranges split.estimation [0, 200] and split.validation [200, null]",
      "either the ranges or validation_fraction"]),
    ("same-column-input-and-output", [("data.inputs", {"x": "u"})],
     ["data.inputs", "column 'x'", "data.outputs: x -> x"]),
    ("decimate-signals", [("prefilter", [{"name": "decimate", "params": {"q": 2}, "signals": ["x"]}])],
     ["prefilter[0].signals", "applies to every input and output"]),
]


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_bad_config_exits_2_naming_file_and_key(folder, case):
    _, spec, mention = case
    text = spec if isinstance(spec, str) else yaml.safe_dump(_with(spec), sort_keys=False, allow_unicode=True)
    _check(folder, text, *mention)


def test_oversized_config_is_refused_before_reading(folder):
    cfg = folder / "c.yaml"
    with open(cfg, "wb") as fh:
        fh.write(yaml.safe_dump(GOOD).encode())
        fh.seek((64 << 20) - 1)   # a sparse 64 MiB file: refused by its size, never read
        fh.write(b"\n")
    res = run_cli("diagnose", str(cfg), "--out", str(folder / "run"), timeout=30)
    assert_bad_input(res, str(cfg), "at most")
    assert not (folder / "run").exists()


def test_directory_as_config(folder):
    res = run_cli("diagnose", str(folder), "--out", str(folder / "run"))
    assert_bad_input(res, "is a directory")


def test_report_draws_user_text_literally(folder):
    """A candidate named like broken mathtext ('$\\frac{') and HTML in a name: the report is written
    (no matplotlib parse error) and the text appears escaped, not interpreted."""
    name = "$\\frac{<b>M1</b>"
    cfg = _with([("structures", {**STRUCT, "candidates": {name: ["v"]}})])
    (folder / "c.yaml").write_text(yaml.safe_dump(cfg, sort_keys=False))
    res = run_cli("report", str(folder / "c.yaml"), "--out", str(folder / "run"))
    assert res.rc == 0, res.stderr[-2000:]
    html = (folder / "run" / "report.html").read_text()
    assert "&lt;b&gt;M1&lt;/b&gt;" in html and "<b>M1</b>" not in html
