"""``cubic_stiffness``: an odd cubic restoring term ``c*x**3`` (Duffing) in the equation of the
velocity of position x (every dynamic equation only with ``diagnose.couplings``)."""

from .base import StateTermFamily


class CubicStiffness(StateTermFamily):
    id = "cubic_stiffness"
    role = "positions"
    template = "{z}**3"
    noun = "A cubic stiffness term"
