"""Config schema (diagnosis contract §1) and loading.

The YAML is validated with pydantic (unknown keys and wrong types are errors), then checked
semantically: equations for exactly the states, free parameters among the params, expression names
known, measured outputs naming states or declared outputs. Every failure is a :class:`ConfigError`
naming the file and the dotted key.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Annotated, Literal, Union

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from .errors import ConfigError
from .expressions import FUNCTIONS, Expr, parse

FAMILIES_V1 = ("offset", "output_offset", "cubic_stiffness", "quadratic_damping", "coulomb_friction",
               "periodic_disturbance", "input_delay", "colored_noise", "heavy_tailed_noise",
               "heteroscedastic_noise")
NOISE_FAMILIES = ("colored_noise", "heavy_tailed_noise", "heteroscedastic_noise")
ALL_FAMILY_IDS = (
    "offset", "output_offset", "cubic_stiffness", "quadratic_damping", "coulomb_friction",
    "static_nonlinearity", "periodic_disturbance", "input_delay", "input_saturation", "dead_zone",
    "parameter_jump", "parameter_drift", "unmodeled_dynamics", "state_saturation", "colored_noise",
    "heavy_tailed_noise", "heteroscedastic_noise",
)


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=False)


def _unique_targets(v: Union[list[str], dict[str, str], None]):
    """Two data columns mapped to one model name would silently drop one of them."""
    if isinstance(v, dict):
        seen: dict[str, str] = {}
        for col, name in v.items():
            if name in seen:
                raise ValueError(f"columns {seen[name]!r} and {col!r} both map to {name!r}; map each model "
                                 "name to one column")
            seen[name] = col
    elif isinstance(v, list) and len(set(v)) != len(v):
        dup = next(c for c in v if v.count(c) > 1)
        raise ValueError(f"column {dup!r} is listed twice")
    return v


class _ReadCfg(_Strict):
    """How one data file is read (pipeline.loaders). Shared by ``data`` and its experiments."""

    format: Literal["csv", "parquet", "mat", "table"] | None = None
    # table (headerless text): the name of every column, in file order; the count must match the file's
    columns: list[str] | None = None
    delimiter: str | None = Field(default=None, min_length=1, max_length=1)  # csv ","; table: whitespace
    decimal: Literal[".", ","] | None = None                     # default "."
    comment: str | None = Field(default=None, min_length=1, max_length=1)  # default "#" (table only)
    skip_rows: int | None = Field(default=None, ge=0)           # lines skipped before header/data

    @field_validator("columns")
    @classmethod
    def _distinct_columns(cls, v):
        return _unique_targets(v)


class ExperimentCfg(_ReadCfg):
    """A separate record (contract §4): keys left out are taken from ``data`` (``time`` and
    ``sample_time`` together: giving either replaces both)."""

    name: str | None = Field(default=None, min_length=1)
    path: str | None = None
    time: str | None = None
    sample_time: float | None = Field(default=None, gt=0, allow_inf_nan=False)
    inputs: Union[list[str], dict[str, str], None] = None
    outputs: Union[list[str], dict[str, str], None] = None
    role: Literal["estimation", "validation"] | None = None

    @field_validator("inputs", "outputs")
    @classmethod
    def _one_column_per_name(cls, v):
        return _unique_targets(v)


class DataCfg(_ReadCfg):
    path: str
    time: str | None = None
    sample_time: float | None = Field(default=None, gt=0, allow_inf_nan=False)
    inputs: Union[list[str], dict[str, str]] = Field(default_factory=list)
    outputs: Union[list[str], dict[str, str]]
    intersample: Literal["zoh", "foh"] = "zoh"
    remove_mean: bool = False
    # largest tolerated relative deviation of a sampling interval from the median one
    max_jitter: float = Field(default=0.01, ge=0, allow_inf_nan=False)
    min_samples: int = Field(default=50, ge=4)
    # bounds checked before a file is read: its size (and, for .mat/Parquet, its decoded size) and rows
    max_bytes: int = Field(default=2 << 30, ge=1)
    max_samples: int = Field(default=50_000_000, ge=1)
    # separate records: one validation record, or a list of experiments with roles (contract §4)
    validation: ExperimentCfg | None = None
    experiments: list[ExperimentCfg] | None = Field(default=None, min_length=1)

    @field_validator("inputs", "outputs")
    @classmethod
    def _one_column_per_name(cls, v):
        return _unique_targets(v)


InitialValue = Union[float, Literal["data", "estimate"]]


class ModelCfg(_Strict):
    states: list[str] = Field(min_length=1)
    inputs: list[str] = Field(default_factory=list)
    params: dict[str, float] = Field(default_factory=dict)
    free: list[str] = Field(default_factory=list)
    equations: dict[str, Union[str, float]]
    initial: Union[dict[str, InitialValue], Literal["data", "estimate"], float] = 0.0
    outputs: dict[str, str] = Field(default_factory=dict)  # declared outputs: name -> expression
    substeps: int = Field(default=1, ge=1, le=64)  # RK4 sub-steps per sample interval


class SplitCfg(_Strict):
    validation_fraction: float = Field(default=0.3, gt=0, lt=1)
    estimation: tuple[int, int | None] | None = None
    validation: tuple[int, int | None] | None = None
    # fitting simulations start this many samples before the estimation part (from the configured
    # initial state) instead of at sample 0; reported errors always use the simulation from sample 0
    warmup: int | None = Field(default=None, ge=0)


class DiagnoseCfg(_Strict):
    families: Union[Literal["all"], list[str]] = "all"
    alpha: float = Field(default=0.01, gt=0, lt=0.5)
    max_findings: int = Field(default=3, ge=0, le=10)
    max_delay_s: float | None = Field(default=None, gt=0)  # search range for input_delay
    bootstrap: int = Field(default=400, ge=50, le=10000)

    @field_validator("families")
    @classmethod
    def _known(cls, v):
        if isinstance(v, list):
            bad = [f for f in v if f not in ALL_FAMILY_IDS]
            if bad:
                raise ValueError(f"unknown family {bad[0]!r}; known: {', '.join(ALL_FAMILY_IDS)}")
        return v


ESTIMATOR_IDS = ("ls", "wls", "iv", "ml", "map", "mcmc", "rls")


class PrefilterStepCfg(_Strict):
    """One prefilter step (pipeline.prefilter): name, parameters, and the signals it applies to."""

    name: Literal["remove_mean", "remove_trend", "lowpass", "state_variable_filter", "notch", "decimate"]
    params: dict[str, Union[float, int, str, bool, None]] = Field(default_factory=dict)
    signals: list[str] | None = None   # model names (inputs/outputs); default: all


class DerivativeCfg(_Strict):
    method: Literal["fd", "savgol", "spline", "tv"] = "savgol"
    window: int = Field(default=11, ge=3)
    polyorder: int = Field(default=3, ge=1)


class LibraryCfg(_Strict):
    """Candidate terms generated from a library (union of the listed families) for ERR/FROLS."""

    poly: dict[str, Union[list[str], int, bool]] | None = None   # {vars: [x], degree: 3}
    tanh: list[str] | None = None
    rational: list[str] | None = None
    sign: list[str] | None = None
    terms: list[str] | None = None
    max_terms: int = Field(default=8, ge=1, le=100)
    criterion: Literal["bic", "aic", "aicc", "fpe"] = "bic"


class SindyCfg(_Strict):
    """SINDy on the unknown part of the equation (pipeline.structures.sindy): threshold(s), several
    chosen by blocked CV; the library is ``terms`` or a cubic polynomial in the equation's state."""

    threshold: Union[float, list[float]] = Field(default_factory=lambda: [0.01, 0.05, 0.1, 0.5])
    optimizer: Literal["stlsq", "sr3"] = "stlsq"
    terms: list[str] | None = None


class TakagiSugenoCfg(_Strict):
    """Takagi–Sugeno model of the unknown part: premise signals, candidate rule counts (K by CV)."""

    inputs: list[str] | None = None       # default: the equation's state
    rules: list[Annotated[int, Field(ge=1)]] = Field(default_factory=lambda: [2, 5, 11], min_length=1)
    method: Literal["global", "local"] = "global"


class StructuresCfg(_Strict):
    """Candidate structures for one state equation: d(equation)/dt = known + Σ θ_i term_i."""

    equation: str
    known: Union[str, float] = 0.0
    candidates: dict[str, list[str]] = Field(default_factory=dict)
    library: LibraryCfg | None = None
    sindy: SindyCfg | None = None
    takagi_sugeno: TakagiSugenoCfg | None = None
    derivative: DerivativeCfg = Field(default_factory=DerivativeCfg)
    cv_folds: int = Field(default=10, ge=2, le=50)
    cv_gap: int = Field(default=10, ge=0)


class Config(_Strict):
    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    seed: int = 0
    data: DataCfg
    model: ModelCfg
    split: SplitCfg = Field(default_factory=SplitCfg)
    diagnose: DiagnoseCfg = Field(default_factory=DiagnoseCfg)
    prefilter: list[PrefilterStepCfg] = Field(default_factory=list)
    structures: StructuresCfg | None = None
    # estimators run on every candidate structure: names or {name: {options}}
    estimators: list[Union[str, dict[str, dict[str, Union[float, int, str, bool, list[float], None]]]]] = \
        Field(default_factory=lambda: ["ls"])

    @field_validator("estimators")
    @classmethod
    def _known_estimators(cls, v):
        for item in v:
            names = [item] if isinstance(item, str) else list(item)
            for n in names:
                if n not in ESTIMATOR_IDS:
                    raise ValueError(f"unknown estimator {n!r}; known: {', '.join(ESTIMATOR_IDS)}")
        return v

    def estimator_list(self) -> list[tuple[str, dict]]:
        out = []
        for item in self.estimators:
            if isinstance(item, str):
                out.append((item, {}))
            else:
                out.extend((k, dict(o or {})) for k, o in item.items())
        return out


class LoadedConfig:
    """A validated config with its source file, parsed expressions and canonical hash."""

    def __init__(self, cfg: Config, path: Path, equations: dict[str, Expr], outputs: dict[str, Expr],
                 input_map: dict[str, str], output_map: dict[str, str]):
        self.cfg = cfg
        self.path = path
        self.equations = equations        # state -> Expr
        self.output_exprs = outputs       # declared output name -> Expr
        self.input_map = input_map        # data column -> model input name
        self.output_map = output_map      # data column -> state or declared output name

    @property
    def data_path(self) -> Path:
        p = Path(self.cfg.data.path)
        return p if p.is_absolute() else (self.path.parent / p)

    def canonical(self) -> dict:
        return self.cfg.model_dump(mode="json")

    def sha256(self) -> str:
        blob = json.dumps(self.canonical(), sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()


def _as_map(v: list[str] | dict[str, str]) -> dict[str, str]:
    return {c: c for c in v} if isinstance(v, list) else dict(v)


def _fmt_loc(loc: tuple) -> str:
    return ".".join(str(x) for x in loc if not str(x).startswith(("function-", "literal[", "union[")))


def load_config(path: str | Path) -> LoadedConfig:
    """Read, validate and check a YAML config. Raises ConfigError (file, key, expectation)."""
    path = Path(path)
    fname = str(path)
    if not path.is_file():
        raise ConfigError("config file not found", file=fname)
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        what = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"not valid YAML{where}: {what}", file=fname) from None
    except UnicodeDecodeError:
        raise ConfigError("not a UTF-8 text file", file=fname) from None
    if not isinstance(raw, dict):
        raise ConfigError("expected a YAML mapping at the top level", file=fname)
    try:
        cfg = Config.model_validate(raw)
    except ValidationError as exc:
        lines = []
        for err in exc.errors():
            key = _fmt_loc(err["loc"]) or "(top level)"
            msg = err["msg"]
            if err["type"] == "extra_forbidden":
                msg = "unknown key"
            elif err["type"] == "missing":
                msg = "required key is missing"
            lines.append(f"{key}: {msg}")
        # one message: the first problem, then any others
        uniq = list(dict.fromkeys(lines))
        raise ConfigError("; ".join(uniq[:5]), file=fname) from None
    return _check(cfg, path)


def _check(cfg: Config, path: Path) -> LoadedConfig:
    f = str(path)
    m = cfg.model
    reserved = set(FUNCTIONS) | {"t", "np", "pi"}
    seen: dict[str, str] = {}
    for kind, names in (("model.states", m.states), ("model.inputs", m.inputs),
                        ("model.params", list(m.params)), ("model.outputs", list(m.outputs))):
        for n in names:
            if not n.isidentifier():
                raise ConfigError(f"{n!r} is not a valid name", file=f, key=kind)
            if n in reserved:
                raise ConfigError(f"{n!r} is reserved (a function name or t)", file=f, key=kind)
            if n in seen:
                raise ConfigError(f"{n!r} is declared twice (also in {seen[n]})", file=f, key=kind)
            seen[n] = kind
    if set(m.equations) != set(m.states):
        missing = [s for s in m.states if s not in m.equations]
        extra = [s for s in m.equations if s not in m.states]
        what = f"no equation for state {missing[0]!r}" if missing else f"{extra[0]!r} is not a state"
        raise ConfigError(what + f" (states: {', '.join(m.states)})", file=f, key="model.equations")
    for p in m.free:
        if p not in m.params:
            raise ConfigError(f"free parameter {p!r} is not in model.params", file=f, key="model.free")
    allowed = set(m.states) | set(m.inputs) | set(m.params) | {"t"}
    eqs = {s: parse(m.equations[s], allowed, where=f"model.equations.{s}", file=f) for s in m.states}
    outs = {o: parse(e, allowed, where=f"model.outputs.{o}", file=f) for o, e in m.outputs.items()}
    if isinstance(m.initial, dict):
        for s in m.initial:
            if s not in m.states:
                raise ConfigError(f"{s!r} is not a state", file=f, key=f"model.initial.{s}")
    imap = _as_map(cfg.data.inputs)
    omap = _as_map(cfg.data.outputs)
    for col, name in imap.items():
        if name not in m.inputs:
            raise ConfigError(f"column {col!r} maps to {name!r}, which is not a model input "
                              f"(model.inputs: {m.inputs})", file=f, key="data.inputs")
    missing_in = [u for u in m.inputs if u not in imap.values()]
    if missing_in:
        raise ConfigError(f"model input {missing_in[0]!r} has no data column", file=f, key="data.inputs")
    if not omap:
        raise ConfigError("at least one measured output is needed", file=f, key="data.outputs")
    for col, name in omap.items():
        if name not in m.states and name not in m.outputs:
            raise ConfigError(f"measured column {col!r} maps to {name!r}, which is neither a state nor a "
                              f"declared output (states: {m.states})", file=f, key="data.outputs")
    if cfg.data.time is None and cfg.data.sample_time is None:
        raise ConfigError("give either data.time (a column) or data.sample_time (seconds)",
                          file=f, key="data")
    if cfg.data.time is not None and cfg.data.sample_time is not None:
        raise ConfigError("give data.time or data.sample_time, not both", file=f, key="data")
    s = cfg.split
    if (s.estimation is None) != (s.validation is None):
        raise ConfigError("give both split.estimation and split.validation, or neither",
                          file=f, key="split")
    if s.warmup is not None:
        init = m.initial if isinstance(m.initial, dict) else {st: m.initial for st in m.states}
        if any(v == "estimate" for v in init.values()):
            raise ConfigError("split.warmup cannot be combined with initial states to 'estimate' (the state at "
                              "the warm-up start would be ambiguous); give numbers or 'data'", file=f, key="split.warmup")
    for key in ("estimation", "validation"):
        rng = getattr(s, key)
        if rng is not None and (rng[0] < 0 or (rng[1] is not None and rng[1] <= rng[0])):
            raise ConfigError(f"expected [start, stop) with 0 <= start < stop, got {list(rng)}",
                              file=f, key=f"split.{key}")
    if cfg.structures is not None:
        st = cfg.structures
        if st.equation not in m.states:
            raise ConfigError(f"{st.equation!r} is not a state (states: {m.states})", file=f, key="structures.equation")
        parse(st.known, allowed, where="structures.known", file=f)
        if not st.candidates and st.library is None and st.sindy is None and st.takagi_sugeno is None:
            raise ConfigError("no candidate structure: give candidates, a library, sindy or takagi_sugeno",
                              file=f, key="structures")
        for name, terms in st.candidates.items():
            if not terms:
                raise ConfigError("empty term list", file=f, key=f"structures.candidates.{name}")
            for i, term in enumerate(terms):
                parse(term, allowed - set(m.params), where=f"structures.candidates.{name}[{i}]", file=f)
    signals = set(imap.values()) | set(omap.values())
    for i, step in enumerate(cfg.prefilter):
        for sig in step.signals or []:
            if sig not in signals:
                raise ConfigError(f"{sig!r} is not a measured signal (known: {sorted(signals)})",
                                  file=f, key=f"prefilter[{i}].signals")
    return LoadedConfig(cfg, path, eqs, outs, imap, omap)
