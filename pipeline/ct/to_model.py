"""A continuous transfer function as a grey-box :class:`~pipeline.model.Model` (so the pipeline's
simulation kernel, fit and diagnosis can use a continuous-time estimate).

G(s) = (b_m s^m + … + b_0)/(a_n s^n + … + a_0), m < n, in controllable canonical form (Kailath 1980,
§2.1): z_i' = z_{i+1} (i < n), z_n' = (u − a_0 z_1 − … − a_{n−1} z_n)/a_n, y = b_0 z_1 + … + b_m z_{m+1}.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..expressions import parse
from ..model import Model


def transfer_function_model(num, den, *, input: str = "u", output: str = "y", intersample: str = "foh",
                            substeps: int = 1, free: bool = False) -> Model:
    """Model with states z1..zn, parameters a0..an and b0..bm (``free=True``: all but a_n free), and a
    declared output ``output``; ``num``/``den`` highest power first, as scipy.signal."""
    num = np.atleast_1d(np.asarray(num, float))
    den = np.atleast_1d(np.asarray(den, float))
    n, m = len(den) - 1, len(num) - 1
    if n < 1 or den[0] == 0:
        raise InputError(f"transfer function: denominator {den.tolist()} must have degree >= 1")
    if m >= n:
        raise InputError(f"transfer function: numerator degree {m} must be below the denominator's {n}")
    a = den[::-1]     # a_0 .. a_n
    b = num[::-1]     # b_0 .. b_m
    states = [f"z{i + 1}" for i in range(n)]
    params = {f"a{i}": float(a[i]) for i in range(n + 1)}
    params.update({f"b{i}": float(b[i]) for i in range(m + 1)})
    allowed = set(states) | {input, "t"} | set(params)
    eqs = {states[i]: parse(states[i + 1], allowed) for i in range(n - 1)}
    eqs[states[-1]] = parse(f"({input} - " + " - ".join(f"a{i}*{states[i]}" for i in range(n)) + f")/a{n}", allowed)
    out = parse(" + ".join(f"b{i}*{states[i]}" for i in range(m + 1)), allowed)
    free_params = tuple(k for k in params if k != f"a{n}") if free else ()
    return Model(states=tuple(states), inputs=(input,), equations=eqs, output_exprs={output: out}, params=params,
                 free=free_params, initial={s: 0.0 for s in states}, substeps=substeps, intersample=intersample,
                 nominal_params=tuple(params))
