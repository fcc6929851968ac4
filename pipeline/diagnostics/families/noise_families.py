"""The noise families (colored_noise, heavy_tailed_noise, heteroscedastic_noise): tested on the final
model by :mod:`pipeline.diagnostics.noise`; registered here so the registry is the one list of ids."""

from .base import Family


class _Noise(Family):
    stage = "noise"

    def hypotheses(self, ctx):
        return []


class ColoredNoise(_Noise):
    id = "colored_noise"


class HeavyTailedNoise(_Noise):
    id = "heavy_tailed_noise"


class HeteroscedasticNoise(_Noise):
    id = "heteroscedastic_noise"
