"""Config schema (diagnosis contract §1) and loading.

The YAML is validated with pydantic (unknown keys and wrong types are errors), then checked
semantically: equations for exactly the states, free parameters among the params, expression names
known, measured outputs naming states or declared outputs. Every failure is a :class:`ConfigError`
naming the file and the dotted key.
"""

from __future__ import annotations

import builtins
import hashlib
import json
import keyword
import re
import unicodedata
from pathlib import Path
from typing import Annotated, Literal, Union

import yaml
from pydantic import BaseModel, ConfigDict, Field, StrictBool, StrictInt, StrictStr, ValidationError, field_validator

from .errors import ConfigError
from .expressions import CONSTANTS, FUNCTIONS, Expr, parse
from .numbers import Finite, Integer, Seed

MAX_CONFIG_BYTES = 4 << 20      # a config is text a person wrote: 4 MiB is far beyond any real one
MAX_YAML_DEPTH = 50             # nesting depth of YAML mappings and lists
MAX_STATES = 100                # one kernel per structure: compile time grows with the equations
MAX_PARAMS = 2000
# names a model may not use: Python keywords, the generated code's own names, functions and constants
RESERVED_NAMES = (set(keyword.kwlist) | set(keyword.softkwlist) | set(FUNCTIONS) | set(CONSTANTS)
                  | {"t", "np", "min", "max", "abs", "xs", "uu", "p", "dx", "k_eq", "k_kind", "k_var", "k_pow",
                     "k_pc", "k_pf", "math", "numba"} | {n for n in dir(builtins) if not n.startswith("_")})

# the contract's vocabulary (§2, §4); the families implemented are the registry's
# (pipeline.diagnostics.families.REGISTRY), read lazily: the registry imports the model, which imports this
ALL_FAMILY_IDS = (
    "offset", "output_offset", "cubic_stiffness", "quadratic_damping", "coulomb_friction",
    "static_nonlinearity", "periodic_disturbance", "input_delay", "input_saturation", "dead_zone",
    "parameter_jump", "parameter_drift", "unmodeled_dynamics", "state_saturation", "colored_noise",
    "heavy_tailed_noise", "heteroscedastic_noise", "intersample",
)


def implemented_families() -> tuple[str, ...]:
    from .diagnostics.families import FAMILY_IDS
    return FAMILY_IDS


def noise_families() -> tuple[str, ...]:
    from .diagnostics.families import NOISE_FAMILY_IDS
    return NOISE_FAMILY_IDS


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
    skip_rows: Annotated[Integer, Field(ge=0)] | None = None   # lines skipped before header/data

    @field_validator("columns")
    @classmethod
    def _distinct_columns(cls, v):
        return _unique_targets(v)

    @field_validator("comment", "delimiter")
    @classmethod
    def _not_part_of_a_number(cls, v):
        # a comment character cuts every line at its first occurrence: a digit, sign, point or exponent
        # letter would cut numbers apart
        if v is not None and (v in "0123456789+-.eE" or v.isspace() and v not in "\t "):
            raise ValueError(f"{v!r} can be part of a number; expected a character that is not a digit, "
                             "sign, '.', 'e' or 'E'")
        return v


class ExperimentCfg(_ReadCfg):
    """A separate record (contract §4): keys left out are taken from ``data`` (``time`` and
    ``sample_time`` together: giving either replaces both)."""

    name: str | None = Field(default=None, min_length=1)
    path: str | None = None
    time: str | None = None
    sample_time: Annotated[Finite, Field(gt=0)] | None = None
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
    sample_time: Annotated[Finite, Field(gt=0)] | None = None
    inputs: Union[list[str], dict[str, str]] = Field(default_factory=list)
    outputs: Union[list[str], dict[str, str]]
    # zoh: held; foh: straight lines; bandlimited: the band-limited signal through the samples
    # (pipeline/bandlimited.py)
    intersample: Literal["zoh", "foh", "bandlimited"] = "zoh"
    remove_mean: StrictBool = False
    # largest tolerated relative deviation of a sampling interval from the median one
    max_jitter: Annotated[Finite, Field(ge=0, le=0.5)] = 0.01
    min_samples: Annotated[Integer, Field(ge=4)] = 50
    # bounds checked before a file is read: its size (and, for .mat/Parquet, its decoded size) and rows
    max_bytes: Annotated[Integer, Field(ge=1)] = 2 << 30
    max_samples: Annotated[Integer, Field(ge=1)] = 1_000_000   # = loaders.spec.DEFAULT_MAX_SAMPLES (why: there)
    # separate records: one validation record, or a list of experiments with roles (contract §4)
    validation: ExperimentCfg | None = None
    experiments: list[ExperimentCfg] | None = Field(default=None, min_length=1)

    @field_validator("inputs", "outputs")
    @classmethod
    def _one_column_per_name(cls, v):
        return _unique_targets(v)


InitialValue = Union[Finite, Literal["data", "estimate"]]


class ModelCfg(_Strict):
    states: list[str] = Field(min_length=1)
    inputs: list[str] = Field(default_factory=list)
    params: dict[str, Finite] = Field(default_factory=dict)
    free: list[str] = Field(default_factory=list)
    equations: dict[str, Union[StrictStr, Finite]]
    initial: Union[dict[str, InitialValue], Literal["data", "estimate"], Finite] = 0.0
    outputs: dict[str, StrictStr] = Field(default_factory=dict)  # declared outputs: name -> expression
    substeps: Annotated[Integer, Field(ge=1, le=64)] = 1  # RK4 sub-steps per sample interval
    # dead time of every input (seconds): u(t - input_delay); written back by extended.yaml
    input_delay: Annotated[Finite, Field(ge=0)] | None = None
    # the inputs model.input_delay acts on (default: every input); e.g. one actuator of two with a dead time
    delayed_inputs: list[StrictStr] | None = None
    # bounds of free parameters, [lower, upper] with null for no bound on that side (a loss coefficient
    # that cannot be negative: {a: [0, null]}); respected by every output-error fit and refit
    bounds: dict[str, tuple[Finite | None, Finite | None]] = Field(default_factory=dict)


class SplitCfg(_Strict):
    validation_fraction: Annotated[Finite, Field(gt=0, lt=1)] = 0.3
    estimation: tuple[Integer, Integer | None] | None = None
    validation: tuple[Integer, Integer | None] | None = None
    # fitting simulations start this many samples before the estimation part (from the configured
    # initial state) instead of at sample 0; that simulation is the one tested and reported on the
    # estimation part, and validation errors use the free run of their own segment (fit.simulate_full)
    warmup: Annotated[Integer, Field(ge=0)] | None = None


class DiagnoseCfg(_Strict):
    families: Union[Literal["all"], list[str]] = "all"
    alpha: Annotated[Finite, Field(gt=0, lt=0.5)] = 0.01
    max_findings: Annotated[Integer, Field(ge=0, le=10)] = 3
    max_delay_s: Annotated[Finite, Field(gt=0)] | None = None  # search range for input_delay
    bootstrap: Annotated[Integer, Field(ge=50, le=10000)] = 400
    # terms of one state in another state's equation (v1*abs(v1) in the equation of v2): only when asked
    couplings: StrictBool = False

    @field_validator("families")
    @classmethod
    def _known(cls, v):
        if isinstance(v, list):
            bad = [f for f in v if f not in ALL_FAMILY_IDS]
            if bad:
                raise ValueError(f"unknown family {bad[0]!r}; known: {', '.join(ALL_FAMILY_IDS)}")
            missing = [f for f in v if f not in implemented_families()]
            if missing:
                raise ValueError(f"family {missing[0]!r} is in the contract but not implemented in this version; "
                                 f"implemented: {', '.join(implemented_families())}")
            twice = next((f for i, f in enumerate(v) if f in v[:i]), None)
            if twice is not None:   # it was tested twice and listed twice in families_tested
                raise ValueError(f"family {twice!r} is listed twice")
        return v


ESTIMATOR_IDS = ("ls", "wls", "iv", "ml", "map", "mcmc", "rls")


# decimation keeps every q-th sample of the record: the time axis and every signal together (pipeline.data.
# apply_prefilters), so a signals list on it was ignored (found by an independent audit) and is refused
DECIMATE_SIGNALS = ("decimate changes the sample time of the whole record, so it applies to every input and "
                    "output together; expected no signals on a decimate step (remove the key)")


class PrefilterStepCfg(_Strict):
    """One prefilter step (pipeline.prefilter): name, parameters, and the signals it applies to."""

    name: Literal["remove_mean", "remove_trend", "lowpass", "state_variable_filter", "notch", "decimate"]
    params: dict[str, Annotated[Union[StrictBool, StrictInt, Finite, StrictStr, None],
                                Field(union_mode="left_to_right")]] = Field(default_factory=dict)
    signals: list[str] | None = None   # model names (inputs/outputs); default: all


class DerivativeCfg(_Strict):
    method: Literal["fd", "savgol", "spline", "tv"] = "savgol"
    window: Annotated[Integer, Field(ge=3, le=10_001)] = 11
    polyorder: Annotated[Integer, Field(ge=1, le=10)] = 3


class PolyCfg(_Strict):
    """All monomials of ``vars`` up to ``degree`` (with the constant unless ``include_bias: false``).
    The degree is bounded: d variables give C(d + degree, degree) terms, a matrix of that many columns
    by the estimation samples (3 variables of degree 10: 286 columns)."""

    vars: list[StrictStr] = Field(min_length=1, max_length=10)
    degree: Annotated[Integer, Field(ge=1, le=10)] = 2
    include_bias: StrictBool = True


class LibraryCfg(_Strict):
    """Candidate terms generated from a library (union of the listed families) for ERR/FROLS."""

    poly: PolyCfg | None = None   # {vars: [x], degree: 3}
    tanh: list[str] | None = None
    rational: list[str] | None = None
    sign: list[str] | None = None
    terms: list[str] | None = None
    max_terms: Annotated[Integer, Field(ge=1, le=100)] = 8
    criterion: Literal["bic", "aic", "aicc", "fpe"] = "bic"


class SindyCfg(_Strict):
    """SINDy on the unknown part of the equation (pipeline.structures.sindy): threshold(s), several
    chosen by blocked CV; the library is ``terms`` or a cubic polynomial in the equation's state."""

    threshold: Union[Annotated[Finite, Field(ge=0)], Annotated[list[Annotated[Finite, Field(ge=0)]],
                                                                Field(min_length=1, max_length=50)]] = \
        Field(default_factory=lambda: [0.01, 0.05, 0.1, 0.5])
    optimizer: Literal["stlsq", "sr3"] = "stlsq"
    terms: list[str] | None = None


class TakagiSugenoCfg(_Strict):
    """Takagi–Sugeno model of the unknown part: premise signals, candidate rule counts (K by CV)."""

    inputs: list[str] | None = None       # default: the equation's state
    rules: list[Annotated[Integer, Field(ge=1, le=200)]] = Field(default_factory=lambda: [2, 5, 11], min_length=1,
                                                                  max_length=20)
    method: Literal["global", "local"] = "global"


class StructuresCfg(_Strict):
    """Candidate structures for one state equation: d(equation)/dt = known + Σ θ_i term_i."""

    equation: str
    known: Union[StrictStr, Finite] = 0.0
    candidates: dict[str, list[str]] = Field(default_factory=dict)
    library: LibraryCfg | None = None
    sindy: SindyCfg | None = None
    takagi_sugeno: TakagiSugenoCfg | None = None
    derivative: DerivativeCfg = Field(default_factory=DerivativeCfg)
    cv_folds: Annotated[Integer, Field(ge=2, le=50)] = 10
    cv_gap: Annotated[Integer, Field(ge=0)] = 10


class Config(_Strict):
    name: str = Field(min_length=1)
    seed: Seed = 0
    data: DataCfg
    model: ModelCfg
    split: SplitCfg = Field(default_factory=SplitCfg)
    diagnose: DiagnoseCfg = Field(default_factory=DiagnoseCfg)
    prefilter: list[PrefilterStepCfg] = Field(default_factory=list)
    structures: StructuresCfg | None = None
    # estimators run on every candidate structure: names or {name: {options}}
    estimators: Annotated[list[Union[StrictStr, dict[str, Union[dict[str, object], None]]]],
                          Field(max_length=50)] = Field(default_factory=lambda: ["ls"])
    # report (issue 10): parameter uncertainty of the final grey-box model ("mcmc": emcee posterior
    # overlaid on the Gauss ellipses) and the units of signals for axis labels, e.g. {x: m, u: N}
    uncertainty: Literal["gauss", "mcmc"] = "gauss"
    units: dict[str, StrictStr] = Field(default_factory=dict)

    @field_validator("name")
    @classmethod
    def _run_folder_name(cls, v):
        # it names the run folder: not hidden (a leading "." hides it from every reader) and not an option
        if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]*", v):
            raise ValueError("expected letters, digits, '_', '.' and '-', starting with a letter, digit or '_' "
                             f"(it names the run folder), got {v!r}")
        return v

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
        """(name, options) pairs with options checked by :mod:`pipeline.estimators.options`."""
        from .estimators.options import validate
        out = []
        for item in self.estimators:
            if isinstance(item, str):
                out.append((item, {}))
            else:
                out.extend((k, validate(k, dict(o or {}))) for k, o in item.items())
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

    def _hashed(self) -> dict:
        d = self.cfg.model_dump(mode="json")
        for key, default in (("uncertainty", "gauss"), ("units", {})):  # report-only keys at their
            if d.get(key) == default:                                   # defaults keep run ids stable
                d.pop(key)
        if not d["model"].get("bounds"):       # a key added later: absent, a config's run id is unchanged
            d["model"].pop("bounds", None)
        return d

    def canonical(self) -> dict:
        """The validated config as written back (config.resolved.yaml, extended.yaml, the report): without
        the default split.validation_fraction when split ranges or separate records decide the split, where
        a written fraction is an error (it would be ignored), and without the default ``estimators`` when
        there is no structures section (written, they are an error), so the file loads again."""
        d = self._hashed()
        c = self.cfg
        if "validation_fraction" not in c.split.model_fields_set and (
                c.split.estimation is not None or c.data.validation is not None or c.data.experiments is not None):
            d["split"].pop("validation_fraction", None)
        if "estimators" not in c.model_fields_set and c.structures is None:
            d.pop("estimators", None)   # the default, refused without a structures section when written
        return d

    def sha256(self) -> str:
        # of the full dump (the default fraction included): run ids of existing configs are unchanged
        blob = json.dumps(self._hashed(), sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()


def _as_map(v: list[str] | dict[str, str]) -> dict[str, str]:
    return {c: c for c in v} if isinstance(v, list) else dict(v)


# pydantic's location tags of the validators a value went through (not keys of the config)
_LOC_TAGS = ("function-", "literal[", "union[", "dict[", "list[", "tuple[", "set[", "nullable[",
             "tagged-union[", "json-or-python[", "lax-or-strict[", "constrained-")


def _fmt_loc(loc: tuple) -> str:
    return ".".join(str(x) for x in loc if not (isinstance(x, str) and x.startswith(_LOC_TAGS)))


class _Loader(yaml.SafeLoader):
    """SafeLoader with YAML 1.2 booleans (only true/false: ``off``, ``no``, ``on``, ``yes`` stay strings,
    so a key ``off`` is not silently ``False``), duplicate keys as errors (PyYAML keeps the last one),
    and no aliases: ``*name`` repeats a node by reference, so nine levels of nine aliases make a
    document of a few hundred bytes that expands to 9⁹ nodes for every check after parsing (the
    "billion laughs"); a config has nothing to gain from them."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.events.AliasEvent):
            event = self.peek_event()
            raise yaml.composer.ComposerError(None, None, f"alias *{event.anchor} found; aliases (and anchors "
                                              "&name) are not supported in a config: write the value out",
                                              event.start_mark)
        return super().compose_node(parent, index)


_Loader.yaml_implicit_resolvers = {
    k: [(tag, rx) for tag, rx in v if tag != "tag:yaml.org,2002:bool"]
    for k, v in yaml.SafeLoader.yaml_implicit_resolvers.items()}
_BOOL12 = re.compile(r"^(?:true|True|TRUE|false|False|FALSE)$")
for _first in "tTfF":
    _Loader.yaml_implicit_resolvers.setdefault(_first, []).insert(0, ("tag:yaml.org,2002:bool", _BOOL12))

# YAML 1.2 floats with an exponent: PyYAML (YAML 1.1) reads 1e5, 4e0 and 1.5e5 as strings (its rule needs
# a dot and a signed exponent), so `k: 1e5` was "expected a number, got str '1e5'"
_EXP12 = re.compile(r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)[eE][-+]?[0-9]+$")
for _first in "-+.0123456789":
    _Loader.yaml_implicit_resolvers.setdefault(_first, []).insert(0, ("tag:yaml.org,2002:float", _EXP12))


def _bool12(loader, node):
    return loader.construct_scalar(node).lower() == "true"


def _mapping_no_duplicates(loader, node, deep=False):
    seen = {}
    for key_node, _ in node.value:
        key = loader.construct_object(key_node, deep=deep)
        try:
            hash(key)
        except TypeError:
            raise yaml.constructor.ConstructorError(None, None, "a mapping key must be a plain value",
                                                    key_node.start_mark) from None
        if key in seen:
            raise yaml.constructor.ConstructorError(
                None, None, f"duplicate key {key!r} (first at line {seen[key] + 1})", key_node.start_mark)
        seen[key] = key_node.start_mark.line
    return loader.construct_mapping(node, deep=deep)


_Loader.add_constructor("tag:yaml.org,2002:bool", _bool12)
_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, _mapping_no_duplicates)


def _depth(obj, limit: int) -> int:
    """Nesting depth of lists and mappings, iteratively (never a RecursionError); stops past ``limit``."""
    stack, deepest = [(obj, 1)], 0
    while stack:
        o, d = stack.pop()
        if isinstance(o, (dict, list)):
            deepest = max(deepest, d)
            if deepest > limit:
                return deepest
            stack.extend((c, d + 1) for c in (o.values() if isinstance(o, dict) else o))
    return deepest


def read_yaml(path: Path, *, what: str = "config", max_bytes: int = MAX_CONFIG_BYTES):
    """Parse a YAML file under the limits above; ConfigError naming the file otherwise."""
    fname = str(path)
    if path.is_dir():
        raise ConfigError(f"is a directory; expected a YAML {what} file", file=fname)
    if not path.is_file():
        raise ConfigError(f"{what} file not found", file=fname)
    size = path.stat().st_size
    if size > max_bytes:
        raise ConfigError(f"{size} bytes; a {what} file may hold at most {max_bytes} bytes", file=fname)
    try:
        with open(path, "rb") as fh:
            text = fh.read(max_bytes + 1).decode("utf-8")
        return yaml.load(text, Loader=_Loader)  # noqa: S506 - _Loader is a SafeLoader
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        what_ = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError(f"not valid YAML{where}: {what_}", file=fname) from None
    except UnicodeDecodeError:
        raise ConfigError("not a UTF-8 text file", file=fname) from None
    except RecursionError:
        raise ConfigError(f"YAML nested too deeply (at most {MAX_YAML_DEPTH} levels)", file=fname) from None


def load_config(path: str | Path) -> LoadedConfig:
    """Read, validate and check a YAML config. Raises ConfigError (file, key, expectation)."""
    path = Path(path)
    fname = str(path)
    raw = read_yaml(path)
    if not isinstance(raw, dict):
        raise ConfigError("expected a YAML mapping at the top level", file=fname)
    if _depth(raw, MAX_YAML_DEPTH) > MAX_YAML_DEPTH:
        raise ConfigError(f"YAML nested too deeply (at most {MAX_YAML_DEPTH} levels)", file=fname)
    bad_keys = _non_string_keys(raw)
    if bad_keys:
        raise ConfigError(f"keys must be text, got {bad_keys[1]!r}", file=fname, key=bad_keys[0] or "(top level)")
    try:
        cfg = Config.model_validate(raw)
    except ValidationError as exc:
        raise ConfigError(_validation_message(exc), file=fname) from None
    return _check(cfg, path)


def _non_string_keys(obj, where: str = ""):
    """(dotted location, key) of the first mapping key that is not a string (``1: x``, ``null: y``)."""
    stack = [(obj, where)]
    while stack:
        o, w = stack.pop()
        if isinstance(o, dict):
            for k, v in o.items():
                if not isinstance(k, str):
                    return (w, k)
                stack.append((v, f"{w}.{k}" if w else k))
        elif isinstance(o, list):
            stack.extend((v, f"{w}[{i}]") for i, v in enumerate(o))
    return None


def _validation_message(exc: ValidationError, prefix: str = "") -> str:
    lines = []
    for err in exc.errors():
        key = _fmt_loc(err["loc"])
        key = (f"{prefix}.{key}" if key else prefix) if prefix else (key or "(top level)")
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key"
        elif err["type"] == "missing":
            msg = "required key is missing"
        msg = msg.removeprefix("Value error, ")
        lines.append(f"{key}: {msg}")
    # one message: the first problem, then any others; one per key (a value that fails every branch of a
    # union, e.g. prior_sd: -1 for "a positive number or a list of them", gets the first branch's reason,
    # not also "Input should be a valid list")
    first: dict[str, str] = {}
    for line in lines:
        first.setdefault(line.split(": ", 1)[0], line)
    return "; ".join(list(first.values())[:5])


def _check_name(n: str, kind: str, f: str) -> None:
    """A model name: an ASCII-or-Unicode identifier in NFKC normal form (Python normalises identifiers,
    so ``ｋ`` would silently be ``k``), not a keyword, not a name the generated code or the language uses."""
    if not isinstance(n, str) or not n.isidentifier():
        raise ConfigError(f"{n!r} is not a valid name (letters, digits and _, not starting with a digit)",
                          file=f, key=kind)
    norm = unicodedata.normalize("NFKC", n)
    if norm != n:
        raise ConfigError(f"{n!r} reads as {norm!r} once normalised (NFKC); write {norm!r}", file=f, key=kind)
    if n in RESERVED_NAMES or n.startswith("_"):
        raise ConfigError(f"{n!r} is reserved (a Python keyword or builtin, a function, pi, t, np, or a name "
                          "of the generated code); choose another name", file=f, key=kind)
    if len(n) > 64:
        raise ConfigError(f"name of {len(n)} characters; at most 64", file=f, key=kind)


def _fmt_range(rng) -> str:
    return f"[{rng[0]}, {'null' if rng[1] is None else rng[1]}]"


def _check_input_output_columns(imap: dict[str, str], omap: dict[str, str], ikey: str, okey: str, f: str) -> None:
    """A data column is an input (fed to the simulation) or a measured output (compared with it), never
    both: the model would be driven by the very signal it is scored on (found by an independent audit)."""
    col = next((c for c in imap if c in omap), None)
    if col is not None:
        raise ConfigError(f"column {col!r} is both an input ({ikey}: {col} -> {imap[col]}) and a measured output "
                          f"({okey}: {col} -> {omap[col]}); expected each data column in one of {ikey} and "
                          f"{okey} only: an input drives the simulation and an output is compared with it",
                          file=f, key=ikey)


def _check(cfg: Config, path: Path) -> LoadedConfig:
    f = str(path)
    m = cfg.model
    if len(m.states) > MAX_STATES:
        raise ConfigError(f"{len(m.states)} states; at most {MAX_STATES} are supported", file=f, key="model.states")
    if len(m.params) > MAX_PARAMS:
        raise ConfigError(f"{len(m.params)} parameters; at most {MAX_PARAMS}", file=f, key="model.params")
    seen: dict[str, str] = {}
    for kind, names in (("model.states", m.states), ("model.inputs", m.inputs),
                        ("model.params", list(m.params)), ("model.outputs", list(m.outputs))):
        for n in names:
            _check_name(n, kind, f)
            if n in seen:
                raise ConfigError(f"{n!r} is declared twice (also in {seen[n]})", file=f, key=kind)
            seen[n] = kind
    if len(set(m.free)) != len(m.free):
        dup = next(p for p in m.free if m.free.count(p) > 1)
        raise ConfigError(f"{dup!r} is listed twice", file=f, key="model.free")
    if set(m.equations) != set(m.states):
        missing = [s for s in m.states if s not in m.equations]
        extra = [s for s in m.equations if s not in m.states]
        what = f"no equation for state {missing[0]!r}" if missing else f"{extra[0]!r} is not a state"
        raise ConfigError(what + f" (states: {', '.join(m.states)})", file=f, key="model.equations")
    for p in m.free:
        if p not in m.params:
            raise ConfigError(f"free parameter {p!r} is not in model.params", file=f, key="model.free")
    for p, (lo, hi) in m.bounds.items():
        key = f"model.bounds.{p}"
        if p not in m.free:
            raise ConfigError(f"{p!r} is not a free parameter (model.free: {', '.join(m.free) or 'none'}): only a "
                              "fitted parameter can be bounded", file=f, key=key)
        if lo is not None and hi is not None and not lo < hi:
            raise ConfigError(f"the lower bound {lo:g} is not below the upper bound {hi:g}", file=f, key=key)
        v = m.params[p]
        if (lo is not None and v < lo) or (hi is not None and v > hi):
            raise ConfigError(f"the starting value {p} = {v:g} (model.params) is outside its bounds "
                              f"[{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]",
                              file=f, key=key)
    allowed = set(m.states) | set(m.inputs) | set(m.params) | {"t"}
    eqs = {s: parse(m.equations[s], allowed, where=f"model.equations.{s}", file=f) for s in m.states}
    outs = {o: parse(e, allowed, where=f"model.outputs.{o}", file=f) for o, e in m.outputs.items()}
    if m.delayed_inputs is not None:
        if m.input_delay is None:
            raise ConfigError("delayed_inputs without model.input_delay: give the dead time in seconds",
                              file=f, key="model.delayed_inputs")
        if not m.delayed_inputs:
            raise ConfigError("an empty list; leave the key out for a delay of every input",
                              file=f, key="model.delayed_inputs")
        for u in m.delayed_inputs:
            if u not in m.inputs:
                raise ConfigError(f"{u!r} is not a model input (model.inputs: {', '.join(m.inputs)})",
                                  file=f, key="model.delayed_inputs")
        if len(set(m.delayed_inputs)) != len(m.delayed_inputs):
            raise ConfigError("an input is listed twice", file=f, key="model.delayed_inputs")
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
    records = [("data.validation", cfg.data.validation)] if cfg.data.validation is not None else []
    records += [(f"data.experiments[{i}]", e) for i, e in enumerate(cfg.data.experiments or [])]
    for key, exp in [("data", cfg.data)] + records:
        # the columns each record reads (keys it leaves out are data's: pipeline.data.sources), and its time
        # column: an input or an output, never both, and the time axis neither
        cols = {side: (getattr(exp, side), f"{key}.{side}") if getattr(exp, side) is not None
                else (getattr(cfg.data, side), f"data.{side}") for side in ("inputs", "outputs")}
        (rins, ikey), (routs, okey) = cols["inputs"], cols["outputs"]
        _check_input_output_columns(_as_map(rins), _as_map(routs), ikey, okey, f)
        own = key == "data" or exp.time is not None or exp.sample_time is not None
        tcol, tkey = (exp.time, f"{key}.time") if own else (cfg.data.time, "data.time")
        for side, (names, skey) in cols.items():
            if tcol is not None and tcol in _as_map(names):
                raise ConfigError(f"column {tcol!r} is the time axis ({tkey}) and also "
                                  f"{'an input' if side == 'inputs' else 'a measured output'} ({skey}); expected the "
                                  "time column apart from the inputs and outputs", file=f, key=tkey)
    for col, name in omap.items():
        if name not in m.states and name not in m.outputs:
            raise ConfigError(f"measured column {col!r} maps to {name!r}, which is neither a state nor a "
                              f"declared output (states: {m.states})", file=f, key="data.outputs")
    if cfg.data.time is None and cfg.data.sample_time is None:
        raise ConfigError("give either data.time (a column) or data.sample_time (seconds)",
                          file=f, key="data")
    named = set(m.states) | set(m.inputs) | set(m.outputs) | set(imap) | set(omap)
    for sig in cfg.units:
        if sig not in named:
            raise ConfigError(f"{sig!r} is not a signal of this config; expected one of "
                              f"{', '.join(sorted(named))}", file=f, key=f"units.{sig}")
    if cfg.data.time is not None and cfg.data.sample_time is not None:
        raise ConfigError("give data.time or data.sample_time, not both", file=f, key="data")
    s = cfg.split
    if (s.estimation is None) != (s.validation is None):
        raise ConfigError("give both split.estimation and split.validation, or neither",
                          file=f, key="split")
    if s.estimation is not None and "validation_fraction" in s.model_fields_set:
        # the ranges decide the split and the fraction was silently ignored (found by an independent audit); only
        # a fraction the user wrote is refused, not the default every config carries
        raise ConfigError(f"{s.validation_fraction:g} given beside the explicit ranges split.estimation "
                          f"{_fmt_range(s.estimation)} and split.validation {_fmt_range(s.validation)}, which decide "
                          "the split (the fraction would be ignored); expected either the ranges or "
                          "validation_fraction, not both", file=f, key="split.validation_fraction")
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
    from .estimators.options import validate as _validate_options
    for i, item in enumerate(cfg.estimators):
        for name, opts in ([(item, {})] if isinstance(item, str) else list(item.items())):
            try:
                _validate_options(name, opts or {})
            except ValidationError as exc:
                raise ConfigError(_validation_message(exc, f"estimators[{i}].{name}"), file=f) from None
    if "estimators" in cfg.model_fields_set and cfg.structures is None:
        # estimators fit the candidate structures: without them the section did nothing (a probe found it
        # accepted with exit 0, while an unknown key anywhere else is an error)
        raise ConfigError("the estimators fit the candidate structures of a structures section, which this "
                          "config does not have: add a structures section (README: The config) or remove "
                          "estimators", file=f, key="estimators")
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
        if step.name == "decimate" and step.signals is not None:
            raise ConfigError(DECIMATE_SIGNALS, file=f, key=f"prefilter[{i}].signals")
        if step.signals is not None and not step.signals:
            # read as "every signal" (the default) until now: an empty list more likely means a list left unfinished
            raise ConfigError("an empty list; expected the signals the step applies to, or no signals key for "
                              "every signal", file=f, key=f"prefilter[{i}].signals")
        for sig in step.signals or []:
            if sig not in signals:
                raise ConfigError(f"{sig!r} is not a measured signal (known: {sorted(signals)})",
                                  file=f, key=f"prefilter[{i}].signals")
    return LoadedConfig(cfg, path, eqs, outs, imap, omap)
