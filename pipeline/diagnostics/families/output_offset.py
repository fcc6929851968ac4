"""``output_offset``: a constant offset ``c`` of a measured output (sensor bias)."""

from .base import Context, Family, Hypothesis, additive


class OutputOffset(Family):
    id = "output_offset"

    def hypotheses(self, ctx: Context) -> list[Hypothesis]:
        return [additive(self.id, ctx.model, y, "1", output=True, suffix=None) for y in ctx.out_names
                if not any(t.is_output and t.target == y for t in ctx.model.terms)]

    def describe(self, hyp, fit, val, sd):
        c = val[hyp.coefs[0]]
        return ({"output": hyp.output, "value": c, "value_std": sd.get(hyp.coefs[0]), "coefficient": c},
                f"The measured output {hyp.output} carries a constant offset of {c:.4g}; removing it")
