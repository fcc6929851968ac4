"""``intersample``: the simulation's own assumption is wrong, the input between samples (zoh vs foh)
or the integration step. Tested before any physical family: the nominal model is refitted with the
other intersample behaviour and with four times the RK4 sub-steps; an alternative that lowers the
held-out free-run error (the engine's gain test) and the estimation BIC (same parameter count) is the
first finding, and the rest of the diagnosis runs on it. A band-limited input sampled and simulated
with zoh otherwise makes null records look like friction or coloured noise."""

from dataclasses import replace

from .base import Family


class Intersample(Family):
    id = "intersample"
    stage = "pre"

    def hypotheses(self, ctx):
        return []

    def alternatives(self, model) -> list[tuple[str, object]]:
        other = "foh" if model.intersample == "zoh" else "zoh"
        return [(other, replace(model, intersample=other)),
                (f"substeps={4 * model.substeps}", replace(model, substeps=min(64, 4 * model.substeps)))]

    def describe_choice(self, model, chosen: str) -> tuple[dict, str]:
        if chosen.startswith("substeps"):
            return ({"chosen": chosen, "configured": f"substeps={model.substeps}"},
                    f"The integration step is too coarse: with {chosen.split('=')[1]} RK4 steps per sample instead "
                    f"of {model.substeps}, the simulation")
        return ({"chosen": chosen, "configured": model.intersample},
                f"The input between samples is better described as {chosen} than as the configured "
                f"{model.intersample} (data.intersample: {chosen}); simulating it so")
