"""Cases: the written config is a valid nominal config (pipeline.config.load_config accepts it), it
does not reveal the effect, the truth names things the config has, and a seed fixes every byte."""

import json

import pandas as pd
import pytest
import yaml

from pipeline.bench.independent import BASES, make_case, menu
from pipeline.config import ALL_FAMILY_IDS, load_config

SAMPLE = [("cubic_stiffness", "msd", "band"), ("static_nonlinearity", "tank", "held"),
          ("input_saturation", "mimo", "band"), ("parameter_jump", "twomode", "prbs"),
          ("state_saturation", "tank", "band"), ("intersample", "dcmotor", "band"),
          ("intersample", "pendulum", "held"), ("output_offset", "dcmotor2", "band"),
          ("unmodeled_dynamics", "msd", "held"), ("none", "mimo", "prbs"), ("hysteresis", "msd", "band"),
          ("wrong_order", "tank", "band"), ("periodic_disturbance", "pendulum", "band"),
          ("parameter_drift", "dcmotor", "held"), ("heteroscedastic_noise", "msd", "band")]


@pytest.mark.parametrize("family,base,kind", SAMPLE, ids=[f"{f}-{b}-{k}" for f, b, k in SAMPLE])
def test_config_is_valid_and_truth_agrees_with_it(tmp_path, family, base, kind):
    case = make_case(family, base, 7, magnitude="medium", noise=0.05, input_kind=kind, n=300, out_dir=tmp_path)
    lc = load_config(case.config_path)
    cfg = lc.cfg
    b = BASES[base]
    truth = json.loads((case.dir / "truth.json").read_text())
    assert truth["family"] == family and truth["base"] == base and truth["seed"] == 7
    assert cfg.model.states == list(b.states) and cfg.model.inputs == list(b.inputs)
    assert set(cfg.model.free) <= set(cfg.model.params)
    frame = pd.read_csv(lc.data_path)
    assert list(frame.columns) == ["t", *b.inputs, *b.measured] and len(frame) == 300
    # the right intersample assumption, except for the intersample family which states the wrong one
    right = "foh" if kind == "band" else "zoh"
    assert truth["intersample_correct"] == right
    assert cfg.data.intersample == (right if family != "intersample" else {"foh": "zoh", "zoh": "foh"}[right])
    if family == "intersample":
        assert truth["params"]["chosen"] == right
    # the config does not reveal the effect: the base's nominal equations and no effect word
    text = (case.dir / "config.yaml").read_text()
    if not (family == "static_nonlinearity" and base == "tank"):
        assert cfg.model.equations == b.equations
    else:
        assert cfg.model.equations == {"h": "b*u - a*h"}     # the user believes a linear outflow
    if family != "intersample":                 # (``intersample`` is a config key by necessity)
        assert family not in text
    assert case.name not in text
    # what the truth acts on exists in the config
    on = truth["acts_on"]
    if "equation" in on:
        assert on["equation"] in cfg.model.states
    if on.get("input", "all") != "all":
        assert on["input"] in cfg.model.inputs
    if "parameter" in on:
        assert on["parameter"] in cfg.model.free
    if "state" in on:
        assert on["state"] in cfg.model.states
    if "output" in on and on["output"] != "all":
        assert on["output"] in cfg.data.outputs


def test_same_arguments_give_identical_bytes_and_another_seed_does_not(tmp_path):
    kw = dict(magnitude="large", noise=0.02, colour="ar0.5", input_kind="held", n=300)
    a = make_case("coulomb_friction", "msd", 3, out_dir=tmp_path / "a", **kw)
    b = make_case("coulomb_friction", "msd", 3, out_dir=tmp_path / "b", **kw)
    c = make_case("coulomb_friction", "msd", 4, out_dir=tmp_path / "c", **kw)
    for f in ("data.csv", "config.yaml", "truth.json"):
        assert (a.dir / f).read_bytes() == (b.dir / f).read_bytes()
    assert (a.dir / "data.csv").read_bytes() != (c.dir / "data.csv").read_bytes()
    assert a.truth["params"]["coefficient"] != c.truth["params"]["coefficient"]


def test_a_fresh_record_keeps_the_truth_and_changes_input_and_noise():
    kw = dict(magnitude="medium", noise=0.02, input_kind="band", n=300)
    a = make_case("cubic_stiffness", "msd", 1, **kw)
    f = make_case("cubic_stiffness", "msd", 1, fresh_seed=1, fresh_n=900, **kw)
    assert f.truth["params"] == a.truth["params"] and len(f.t) == 900
    assert not (f.U[:300] == a.U).all()


def test_does_not_overwrite_a_folder_it_did_not_write(tmp_path):
    case = make_case("none", "dcmotor", 0, n=200, out_dir=tmp_path)
    make_case("none", "dcmotor", 0, n=200, out_dir=tmp_path)        # its own folder: rewritten
    (case.dir / "notes.txt").write_text("mine")
    with pytest.raises(FileExistsError):
        make_case("none", "dcmotor", 0, n=200, out_dir=tmp_path)
    assert (case.dir / "notes.txt").read_text() == "mine"


def test_menu_covers_every_contract_family_and_rejects_unknowns():
    m = menu()
    effects = {f for f, v in m["families"].items() if v["kind"] == "effect"}
    assert set(ALL_FAMILY_IDS) | {"intersample"} <= effects
    oov = {f for f, v in m["families"].items() if v["kind"] == "out_of_vocabulary"}
    assert len(oov) >= 4
    assert set(m["bases"]) == set(BASES) and len(BASES) >= 6
    with pytest.raises(ValueError):
        make_case("no_such_family", "msd", 0, n=100)
    with pytest.raises(ValueError):
        make_case("cubic_stiffness", "tank", 0, n=100)     # no position state in a tank


def test_truth_is_plain_json_with_the_contract_key_parameters(tmp_path):
    keys = {"offset": {"equation", "coefficient"}, "output_offset": {"output", "value"},
            "periodic_disturbance": {"equation", "frequency_hz", "amplitude"}, "input_delay": {"delay_s"},
            "input_saturation": {"limit"}, "dead_zone": {"width"},
            "parameter_jump": {"parameter", "time_s", "before", "after"},
            "parameter_drift": {"parameter", "rate_per_s"}, "unmodeled_dynamics": {"time_constant_s"},
            "state_saturation": {"state", "limit"}, "colored_noise": {"correlation_time_s"},
            "heavy_tailed_noise": {"df"}, "static_nonlinearity": {"equation", "term", "coefficient"}}
    for fam, need in keys.items():
        case = make_case(fam, "msd" if fam != "static_nonlinearity" else "tank", 2, n=200, out_dir=tmp_path)
        truth = json.loads((case.dir / "truth.json").read_text())
        assert need <= set(truth["params"]), fam
        assert yaml.safe_load((case.dir / "config.yaml").read_text())["diagnose"]["families"] == "all"
