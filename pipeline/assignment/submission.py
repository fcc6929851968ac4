"""The submission format, validated.

A submission is one folder per student, named by the student id, under the submissions folder::

    submissions/<student id>/
      config.yaml    the student's extended model: the issued starter config with their extension
                     (a normal pipeline config, diagnosis contract §1); its data.path names the record
      record.csv     the record the student was issued, unchanged (its sha256 is checked against the key)
      answer.yaml    the student's answer, below

``answer.yaml``::

    cause: cubic_stiffness   # the family id of the cause (diagnosis contract §2)
    parameter: k3            # the free parameter of config.yaml that sizes the cause: the coefficient of
                             # the added term (offset, cubic_stiffness, quadratic_damping,
                             # coulomb_friction), the amplitude (periodic_disturbance) or the offset
                             # of the measured output (output_offset); for input_delay the word
                             # input_delay (or model.input_delay): the config's model.input_delay
                             # (the dead time in seconds, fixed)
    claimed_gain: 0.62       # relative validation gain 1 - RMSE(your model) / RMSE(starter model), free-run
                             # simulation, on the validation part of your record as your config splits it
    comment: "optional free text"

Rules for ``config.yaml``: keep the issued input and output columns; no ``prefilter`` and no
``data.remove_mean`` (the grader scores the raw held-out record). Nothing in the answer is trusted:
the grader refits the config and measures everything itself (:mod:`pipeline.assignment.grade`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from ..config import ALL_FAMILY_IDS, LoadedConfig, load_config
from ..errors import InputError
from .template import read_yaml_mapping, validation_message

CONFIG_FILE = "config.yaml"
# answer.parameter naming the config's model.input_delay (the student README does not name it: no hint)
DELAY_ANSWERS = ("input_delay", "model.input_delay")
ANSWER_FILE = "answer.yaml"


class Answer(BaseModel):
    """``answer.yaml`` (unknown keys are errors)."""

    model_config = ConfigDict(extra="forbid")

    cause: str
    parameter: str = Field(min_length=1)
    claimed_gain: float
    comment: str | None = None

    @field_validator("cause")
    @classmethod
    def _family(cls, v: str) -> str:
        if v not in ALL_FAMILY_IDS:
            raise ValueError(f"unknown family {v!r}; a family id of the diagnosis contract §2 "
                             f"({', '.join(ALL_FAMILY_IDS)})")
        return v

    @field_validator("claimed_gain")
    @classmethod
    def _gain(cls, v: float) -> float:
        if not math.isfinite(v) or v > 1:
            raise ValueError(f"a relative gain is a finite number at most 1, got {v}")
        return v


@dataclass
class Submission:
    folder: Path
    config: LoadedConfig
    answer: Answer


def load_answer(path: Path) -> Answer:
    raw = read_yaml_mapping(path, "answer file")
    try:
        return Answer.model_validate(raw)
    except ValidationError as exc:
        raise InputError(validation_message(exc), file=str(path)) from None


def load_submission(folder: Path) -> Submission:
    """Validate one submission folder. Raises InputError naming the file and the key."""
    cfg_path, ans_path = folder / CONFIG_FILE, folder / ANSWER_FILE
    for p in (cfg_path, ans_path):
        if not p.is_file():
            raise InputError("not in the submission", file=str(p))
    lc = load_config(cfg_path)
    answer = load_answer(ans_path)
    if lc.cfg.prefilter:
        raise InputError("prefilter is not allowed in a submission (the held-out record is scored raw)",
                         file=str(cfg_path), key="prefilter")
    if lc.cfg.data.remove_mean:
        raise InputError("remove_mean is not allowed in a submission (the held-out record is scored raw)",
                         file=str(cfg_path), key="data.remove_mean")
    if answer.parameter in DELAY_ANSWERS and answer.parameter not in lc.cfg.model.free:
        if lc.cfg.model.input_delay is None:
            raise InputError(f"{answer.parameter} names model.input_delay, which {CONFIG_FILE} does not set",
                             file=str(ans_path), key="parameter")
    elif answer.parameter not in lc.cfg.model.free:
        raise InputError(f"{answer.parameter!r} is not a free parameter of {CONFIG_FILE} "
                         f"(model.free: {', '.join(lc.cfg.model.free) or 'none'})", file=str(ans_path),
                         key="parameter")
    return Submission(folder, lc, answer)


def student_readme(assignment: str, system_text: str) -> str:
    """The instructions in every student folder: the same text for everyone, no hint."""
    return f"""# Assignment {assignment}

`record.csv` is your measured record of a {system_text}; `config.yaml` is the model you were
taught (the starter config). Your record is yours: every student has a different one.

1. Run the pipeline on the starter config (`sysid report config.yaml`) and find what the simulation
   gets wrong.
2. Name the cause (a family id of the diagnosis contract, section 2).
3. Extend the model in `config.yaml` with a term for that cause and fit it.
4. Report the gain of your model over the starter model on the validation part of your record.

Hand in this folder with `config.yaml` (your extended model), `record.csv` unchanged, and
`answer.yaml`:

```yaml
cause: <family id>
parameter: <the free parameter of config.yaml that sizes the cause, or the model setting that states it>
claimed_gain: <1 - RMSE(your model) / RMSE(starter model) on your validation part>
```

Your model is refitted and scored on data you do not have; the data file is checked against the one
you were issued. Keep the input and output columns; do not add prefilter or remove_mean.
"""
