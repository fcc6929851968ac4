"""``coulomb_friction``: dry friction ``c*sign(v)`` in the equation of velocity v itself. Only for
velocities that change sign (at least 2 % of the simulated samples of each sign): for a state of one
sign, sign(v) is the constant of the ``offset`` family."""

import numpy as np

from .base import Context, StateTermFamily


class CoulombFriction(StateTermFamily):
    id = "coulomb_friction"
    role = "velocities"
    template = "sign({z})"
    noun = "Coulomb friction"

    def admissible(self, ctx: Context, z: str) -> bool:
        x = ctx.state(z)
        return min(np.mean(x > 0), np.mean(x < 0)) >= 0.02
