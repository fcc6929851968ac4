"""``quadratic_damping``: drag ``c*v*abs(v)`` in the equation of velocity v itself."""

from .base import StateTermFamily


class QuadraticDamping(StateTermFamily):
    id = "quadratic_damping"
    role = "velocities"
    template = "{z}*abs({z})"
    noun = "Quadratic damping"
