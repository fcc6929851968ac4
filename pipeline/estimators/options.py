"""Config-facing options of each estimator, as typed, range-checked pydantic models.

``estimators: [ls, {mcmc: {nwalkers: 32, nsteps: 2000}}, ...]`` in a config is validated here, at load
time, before any fit: an unknown option, a wrong type (``lam: 'abc'``, ``true`` as a number, a string as a
bool) or an absurd size (``nsteps: 1e9`` would allocate hundreds of GiB) is one error naming the key.
Array-valued arguments of the estimators (weights, instruments, priors as objects) are internal and not
config options. Bounds are documented on each field.
"""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import BaseModel, ConfigDict, Field, StrictBool, model_validator

from .ml import DENSITIES
from ..numbers import Finite, Integer


class _Opts(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True)


PositiveFinite = Annotated[Finite, Field(gt=0)]


class LsOptions(_Opts):
    min_norm: StrictBool = False
    rtol: PositiveFinite | None = None


class WlsOptions(_Opts):
    fgls: StrictBool = False
    n_iter: Annotated[Integer, Field(ge=1, le=100)] = 5
    scale_cov: StrictBool | None = None


class IvOptions(_Opts):
    delays: Annotated[list[Annotated[Integer, Field(ge=0, le=10_000)]], Field(max_length=20)] | None = None
    ma_lags: Annotated[Integer, Field(ge=0, le=50)] = 0


class MlOptions(_Opts):
    density: Literal[DENSITIES] = "gaussian"  # type: ignore[valid-type]
    sigma: PositiveFinite | None = None
    loc: Finite = 0.0
    nu: PositiveFinite | None = None
    low: Finite | None = None
    high: Finite | None = None
    mode: Finite | None = None

    @model_validator(mode="after")
    def _ordered_bounds(self):
        if self.low is not None and self.high is not None and not self.low < self.high:
            raise ValueError(f"low ({self.low:g}) must be below high ({self.high:g})")
        if self.mode is not None and self.low is not None and self.high is not None \
                and not self.low <= self.mode <= self.high:
            raise ValueError(f"mode ({self.mode:g}) must lie in [low, high] = [{self.low:g}, {self.high:g}]")
        return self


PriorValue = Union[Finite, Annotated[list[Finite], Field(min_length=1, max_length=1000)]]
PriorSd = Union[PositiveFinite, Annotated[list[PositiveFinite], Field(min_length=1, max_length=1000)]]


class MapOptions(_Opts):
    prior_mean: PriorValue = 0.0
    prior_sd: PriorSd = 10.0
    sigma: PositiveFinite | None = None


class McmcOptions(MapOptions):
    nwalkers: Annotated[Integer, Field(ge=2, le=1024)] = 32
    nsteps: Annotated[Integer, Field(ge=10, le=200_000)] = 2000
    init_scale: PositiveFinite = 0.1
    min_tau_multiple: PositiveFinite = 50.0

    @model_validator(mode="after")
    def _bounded_chain(self):
        # the chain is stored as nwalkers × nsteps × p doubles; keep it well under a GiB for p ≤ 50
        if self.nwalkers * self.nsteps > 2_000_000:
            raise ValueError(f"nwalkers × nsteps = {self.nwalkers * self.nsteps} samples; at most 2 000 000 "
                             "(the chain is held in memory)")
        return self


class RlsOptions(_Opts):
    lam: Annotated[Finite, Field(gt=0, le=1)] = 1.0
    p0: PositiveFinite = 1e4
    reset_every: Annotated[Integer, Field(ge=1)] | None = None


OPTIONS: dict[str, type[_Opts]] = {"ls": LsOptions, "wls": WlsOptions, "iv": IvOptions, "ml": MlOptions,
                                   "map": MapOptions, "mcmc": McmcOptions, "rls": RlsOptions}


def validate(name: str, options: dict) -> dict:
    """The options as given, checked against the estimator's schema (only the keys the user set are
    returned, so the estimators' own defaults stay in one place). Raises pydantic ValidationError."""
    model = OPTIONS[name].model_validate(options or {})
    return model.model_dump(exclude_unset=True)
