"""``intersample``: the simulation's own assumption is wrong, the input between samples (zoh, foh or
the band-limited signal) or the integration step. Tested before any physical family: the nominal model
is refitted with the other intersample behaviours (``OTHERS``) and with four times the RK4 sub-steps;
an alternative that lowers the held-out free-run error (the engine's gain test) and the estimation BIC
by more than 2 (same parameter count; ``intersample_stage.INTERSAMPLE_MAX_DBIC``) is the first finding, and the
rest of the diagnosis runs on it. A band-limited input sampled and simulated
with zoh otherwise makes null records look like friction or coloured noise."""

import ast
from dataclasses import replace

from ...model import fresh_name
from .base import Family


def time_steps(model) -> list[float]:
    """The times t_j of every ``step(t − t_j)`` in the model's equations (rewrites written out), t_j a
    number or a parameter: where the right-hand side jumps in time (a ``parameter_jump`` extension)."""
    out = []
    for text in model.describe_equations().values():
        for node in ast.walk(ast.parse(text, mode="eval")):
            if not (isinstance(node, ast.Call) and getattr(node.func, "id", None) == "step" and len(node.args) == 1):
                continue
            a = node.args[0]
            if not (isinstance(a, ast.BinOp) and isinstance(a.op, ast.Sub) and getattr(a.left, "id", None) == "t"):
                continue
            if isinstance(a.right, ast.Constant) and isinstance(a.right.value, (int, float)):
                out.append(float(a.right.value))
            elif isinstance(a.right, ast.Name) and a.right.id in model.params:
                out.append(float(model.params[a.right.id]))
    return sorted(set(out))


class Intersample(Family):
    id = "intersample"
    stage = "pre"

    def hypotheses(self, ctx):
        return []

    # the interpolations tried from each configured one. The band-limited signal from both others: a
    # smooth input is neither steps nor straight lines (the foh's in-band deficit, (ωT)²/12, reaches the
    # output of a plant that rolls off as b/ω² as an apparent feedthrough −bT²/12·u; pipeline/bandlimited.py),
    # and zoh is the contract's default, so a smooth input configured with it must be able to reach it in
    # one step (the stage chooses once); on a held input it rings at every step and loses
    OTHERS = {"zoh": ("foh", "bandlimited"), "foh": ("zoh", "bandlimited"), "bandlimited": ("foh", "zoh")}

    def alternatives(self, model) -> list[tuple[str, object]]:
        return [(o, replace(model, intersample=o)) for o in self.OTHERS[model.intersample]] + [
            (f"substeps={4 * model.substeps}", replace(model, substeps=min(64, 4 * model.substeps)))]

    def equivalent(self, model, chosen: str, dt: float):
        """The physical reading the data cannot tell from a switch to zoh: the configured foh with an input
        dead time of half a sample more (the model's own delay, if it has one, plus dt/2), or None.

        Held on [kT, (k+1)T), the zoh input lags the foh interpolation through the same samples by half
        a sample on average; through a plant whose bandwidth is well below the sampling rate the two
        simulations then differ by a T/2 shift plus terms of order (ωT)² (the hold's frequency response
        is e^{−jωT/2} sinc(ωT/2), a T/2 delay well below the sampling rate; Åström & Wittenmark,
        *Computer-Controlled Systems*, on the hold circuit).
        On the independent bench a switch to zoh and the foh with a fixed T/2 dead time gave the same
        validation RMSE within 0.15 % on seven records, held and smooth inputs alike (BENCHMARKS.md). The
        opposite switch (to foh) is a half-sample *advance*, which no physical family is."""
        if chosen != "zoh" or model.intersample != "foh":
            return None
        if model.delay is not None:
            if model.delay_inputs and set(model.delay_inputs) != set(model.inputs):
                return None          # a dead time on some inputs only: the switch shifts every input
            return replace(model, params={**model.params, model.delay: model.params[model.delay] + dt / 2})
        name = fresh_name(model, "input_delay_s")
        return replace(model, params={**model.params, name: dt / 2}, delay=name)

    def describe_choice(self, model, chosen: str) -> tuple[dict, str]:
        if chosen.startswith("substeps"):
            jumps = time_steps(model)
            key = {"chosen": chosen, "configured": f"substeps={model.substeps}"}
            if jumps:
                # the right-hand side jumps in time (a parameter_jump found before): RK4 loses its order across
                # the jump, and a finer step places it more finely (an auditor's k jump at 29.975 s, between two
                # samples, got "the integration step is too coarse" with nothing about the jump)
                at = ", ".join(f"{tj:.6g}" for tj in jumps)
                return ({**key, "at_jumps_s": jumps},
                        f"The integration step is too coarse for the model's jump in time (t = {at} s): a fixed RK4 "
                        f"step loses its order across a discontinuity and places it only to half a step; with "
                        f"{chosen.split('=')[1]} RK4 steps per sample instead of {model.substeps}, the simulation")
            return (key, f"The integration step is too coarse: with {chosen.split('=')[1]} RK4 steps per sample "
                         f"instead of {model.substeps}, the simulation")
        if chosen == "bandlimited":
            return ({"chosen": chosen, "configured": model.intersample},
                    f"The input between samples is the band-limited signal through its samples, smoother than "
                    f"the configured {model.intersample}'s "
                    + ("straight lines (data.intersample: bandlimited; the straight lines miss (ωT)²/12 of each "
                       "frequency's amplitude, which a plant rolling off above its resonance turns into an "
                       "apparent direct feedthrough)" if model.intersample == "foh" else
                       "steps (data.intersample: bandlimited)") + "; simulating it so")
        return ({"chosen": chosen, "configured": model.intersample},
                f"The input between samples is better described as {chosen} than as the configured "
                f"{model.intersample} (data.intersample: {chosen}); simulating it so")
