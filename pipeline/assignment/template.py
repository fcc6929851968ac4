"""The assignment template: which base system, which hidden effects (with size ranges), how long the
records are, the noise level, and the rubric weights.

```yaml
name: msd-lab3                 # assignment name: prefix of every student's run name
system: msd                    # base system of pipeline.synthetic (msd, pendulum, tank, dcmotor)
samples: 3000                  # samples in each student's record
heldout_samples: 1500          # samples after them that only the instructor has (the held-out part)
noise: 0.02                    # measurement noise, x std of the output
seed: 0                        # default of `sysid assignment make --seed`
families:                      # hidden effects that may be drawn, each with its strength range
  cubic_stiffness: [0.7, 1.3]  #   (strength 1 = the generator's "clearly visible" size)
  coulomb_friction: [0.7, 1.3]
rubric:                        # see pipeline.assignment.rubric for the score
  weights: {cause: 40, parameter: 20, validation: 30, gain: 10}
  parameter_tolerance: 0.25
  delay_tolerance_samples: 1.5 #   input_delay: |delay error| in samples with full marks
  validation_target: 0.8
  gain_tolerance: 0.05
  require_issued_data: true
```

Validated with pydantic (unknown keys and wrong types are errors); every failure is an
:class:`~pipeline.errors.InputError` naming the file and the dotted key.
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

import yaml
from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator, model_validator

from ..errors import InputError
from ..synthetic import BASE

# families a student can write as an extension of the starter config (input_delay as model.input_delay;
# its strength 1 is a dead time of five samples)
GRADABLE_FAMILIES = ("offset", "output_offset", "cubic_stiffness", "quadratic_damping", "coulomb_friction",
                     "periodic_disturbance", "input_delay")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)   # .nan got "less than or equal to 0.5"


class RubricWeights(_Strict):
    """Points of each rubric item (any non-negative numbers; the score is scaled to 100)."""

    cause: float = Field(default=40.0, ge=0)
    parameter: float = Field(default=20.0, ge=0)
    validation: float = Field(default=30.0, ge=0)
    gain: float = Field(default=10.0, ge=0)

    @model_validator(mode="after")
    def _positive_total(self):
        if self.cause + self.parameter + self.validation + self.gain <= 0:
            raise ValueError("the weights sum to 0; give at least one positive weight")
        return self


class Rubric(_Strict):
    weights: RubricWeights = Field(default_factory=RubricWeights)
    parameter_tolerance: float = Field(default=0.25, gt=0, le=10)   # relative error with full marks
    delay_tolerance_samples: float = Field(default=1.5, gt=0, le=100)  # input_delay: error in samples
    validation_target: float = Field(default=0.8, gt=0, le=1)       # share of the achievable gain for full marks
    gain_tolerance: float = Field(default=0.05, gt=0, le=1)         # |claimed - measured| that reproduces
    require_issued_data: bool = True                                # a data file not issued scores 0


class Template(_Strict):
    name: str = Field(min_length=1, max_length=60, pattern=r"^[A-Za-z0-9_.-]+$")
    system: Literal["msd", "pendulum", "tank", "dcmotor"]
    samples: int = Field(default=3000, ge=200, le=200_000)
    heldout_samples: int = Field(default=1500, ge=100, le=200_000)
    noise: float = Field(default=0.02, ge=0, le=0.5)
    seed: int = Field(default=0, ge=0, lt=2 ** 63)
    families: dict[str, tuple[float, float]] = Field(min_length=1)
    rubric: Rubric = Field(default_factory=Rubric)

    @field_validator("families")
    @classmethod
    def _families(cls, v: dict[str, tuple[float, float]]):
        for fam, (lo, hi) in v.items():
            if fam not in GRADABLE_FAMILIES:
                raise ValueError(f"unknown or ungradable family {fam!r}; gradable: {', '.join(GRADABLE_FAMILIES)}")
            if not (0 < lo <= hi <= 5):
                raise ValueError(f"{fam}: strength range must satisfy 0 < low <= high <= 5, got [{lo}, {hi}]")
        return v


def _loc(loc: tuple) -> str:
    return ".".join(str(x) for x in loc if not str(x).startswith(("function-", "literal[", "union[")))


def validation_message(exc: ValidationError) -> str:
    """One line from a pydantic error: ``key: problem`` for the first few problems."""
    lines = []
    for err in exc.errors():
        key = _loc(err["loc"]) or "(top level)"
        msg = {"extra_forbidden": "unknown key", "missing": "required key is missing"}.get(err["type"], err["msg"])
        lines.append(f"{key}: {msg}")
    return "; ".join(list(dict.fromkeys(lines))[:5])


def read_yaml_mapping(path: Path, what: str) -> dict:
    """A YAML file's top-level mapping; InputError (file) when missing, unreadable or not a mapping."""
    f = str(path)
    if not path.is_file():
        raise InputError(f"{what} not found", file=f)
    try:
        raw = yaml.safe_load(path.read_text(encoding="utf-8"))
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        raise InputError(f"not valid YAML{where}: {getattr(exc, 'problem', None) or exc}", file=f) from None
    except UnicodeDecodeError:
        raise InputError("not a UTF-8 text file", file=f) from None
    if not isinstance(raw, dict):
        raise InputError("expected a YAML mapping at the top level", file=f)
    return raw


def load_template(path: str | Path) -> Template:
    """Read and validate an assignment template. Raises InputError naming the file and key."""
    path = Path(path)
    raw = read_yaml_mapping(path, "template")
    try:
        tpl = Template.model_validate(raw)
    except ValidationError as exc:
        raise InputError(validation_message(exc), file=str(path)) from None
    assert tpl.system in BASE
    return tpl
