"""Small helpers for the estimator tests (parsing the seed cases' printed fractions)."""

from __future__ import annotations

from fractions import Fraction


def frac(text) -> Fraction:
    """'14.5/14 = 1.0357143' -> Fraction(29, 28); '4/5' -> Fraction(4, 5); 1 -> Fraction(1)."""
    if isinstance(text, (int, float)):
        return Fraction(text).limit_denominator(10**9)
    head = str(text).split("=")[0].strip()
    if "/" in head:
        num, den = head.split("/")
        return Fraction(num.strip()) / Fraction(den.strip())
    return Fraction(head)


EXACT = 1e-12  # seed_cases.yaml tolerance_semantics: 'exact' = rational arithmetic or 1e-12
