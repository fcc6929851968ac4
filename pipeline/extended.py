"""``extended.yaml``: the final model of a run written back as a runnable config (contract §4).

The config is the run's own config with the model replaced by the final (extended) model: extension
terms written into the equations in the expression language (``pi`` included), their coefficients as
parameters (free, starting at the fitted values, so a rerun converges to the same numbers), the
nominal parameters at their fitted values, a sensor offset as a declared output ``<y>_measured = y + c``
that the measured column then maps to, a found dead time as ``model.input_delay`` (fixed), and the
final model's input interpolation and RK4 steps (``data.intersample``, ``model.substeps``: an intersample
finding).
Noise-model findings change how the model is fitted, not the model, and are not written here.
"""

from __future__ import annotations

from pathlib import Path

from .model import Model


def extended_config(canonical: dict, model: Model, config_path: Path, data_path: Path, target: Path) -> dict:
    """``canonical``: the run's validated config as a dict; ``model``: the final fitted model."""
    cfg = {k: v for k, v in canonical.items() if k not in ("structures", "estimators")}
    cfg["name"] = f"{canonical['name']}-extended"
    m = dict(canonical["model"])
    data = dict(canonical["data"])
    eqs = model.describe_equations()
    m["equations"] = {s: eqs[s] for s in model.states}
    if model.extra_states:  # e.g. an actuator lag: a state of its own, from its initial value
        m["states"] = list(model.states)
        init = m.get("initial", 0.0)
        init = dict(init) if isinstance(init, dict) else {s: init for s in model.nominal_states}
        init.update({s: model.initial[s] for s in model.extra_states})
        m["initial"] = init
    params = {k: float(v) for k, v in model.params.items() if k != model.delay}
    m["params"] = params
    m["free"] = list(dict.fromkeys([k for k in model.free if k != model.delay]))
    # an intersample finding changes the simulation, not the equations: the chosen input interpolation
    # and integration step are the final model's too
    data["intersample"] = model.intersample
    m["substeps"] = int(model.substeps)
    if model.delay is not None:
        m["input_delay"] = float(model.params[model.delay])
        if model.delay_inputs:
            m["delayed_inputs"] = list(model.delay_inputs)
    outs = dict(m.get("outputs") or {})
    offsets = [t for t in model.terms if t.is_output]
    if offsets:
        omap = data["outputs"] if isinstance(data["outputs"], dict) else {c: c for c in data["outputs"]}
        for term in offsets:
            base = outs.get(term.target, term.target)
            name = f"{term.target}_measured"
            outs[name] = f"{base} + {term.coef}" if term.label == "1" else f"{base} + {term.coef}*({term.label})"
            omap = {col: (name if tgt == term.target else tgt) for col, tgt in omap.items()}
        data["outputs"] = omap
    if outs:
        m["outputs"] = outs
    cfg["model"] = m
    # absolute paths: the file is the same whichever folder the run is written to (and reruns into
    # another folder give the same bytes)
    base = Path(config_path).resolve().parent
    data["path"] = str(data_path.resolve())
    for key in ("validation",):
        if isinstance(data.get(key), dict):
            data[key] = _rebase(data[key], base, data["path"], offsets)
    if isinstance(data.get("experiments"), list):
        data["experiments"] = [_rebase(e, base, data["path"], offsets) for e in data["experiments"]]
    cfg["data"] = data
    return _drop_empty(cfg)


def _rebase(exp: dict, base: Path, default: str, offsets) -> dict:
    """An experiment's path made absolute (relative ones are relative to the config's folder) and its
    measured columns renamed like the top-level ones when a sensor offset became a declared output."""
    exp = dict(exp)
    if exp.get("path"):
        p = Path(exp["path"])
        exp["path"] = str(p if p.is_absolute() else (base / p).resolve())
    outs = exp.get("outputs")
    if outs and offsets:
        omap = outs if isinstance(outs, dict) else {c: c for c in outs}
        for term in offsets:
            omap = {col: (f"{term.target}_measured" if tgt == term.target else tgt) for col, tgt in omap.items()}
        exp["outputs"] = omap
    return exp


def _drop_empty(x):
    """Without keys whose value is null or an empty list/mapping (their defaults), for a readable file."""
    if isinstance(x, dict):
        out = {k: _drop_empty(v) for k, v in x.items()}
        return {k: v for k, v in out.items() if v is not None and v != {} and v != []}
    if isinstance(x, list):
        return [_drop_empty(v) for v in x]
    return x
