"""Model-structure selection: term libraries, ERR/FROLS, SINDy and Takagi–Sugeno models (issue 4)."""

from pipeline.structures.library import (
    Library, Term, fit_least_squares, from_terms, lags, narx, parse_term, poly, rational, rbf, saturation, sign,
    sinusoids, tanh,
)
from pipeline.structures.frols import FrolsResult, frols, frols_library

__all__ = [
    "Library", "Term", "parse_term", "from_terms", "poly", "tanh", "rational", "rbf", "sign", "saturation",
    "sinusoids", "lags", "narx", "fit_least_squares", "FrolsResult", "frols", "frols_library",
]
