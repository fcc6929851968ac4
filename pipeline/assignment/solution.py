"""The reference extension of a starter config: the hidden effect's term written into the model, as a
student who found the right cause would write it. Used for the solutions, the tests and the benchmark.

Terms (diagnosis contract §2, additive in the named state equation; ``pos``/``vel`` are the base
system's position and velocity states of :data:`pipeline.synthetic.BASE`)::

    offset                d(eq)/dt = nominal + p_fix
    cubic_stiffness       d(eq)/dt = nominal + p_fix*pos**3
    quadratic_damping     d(eq)/dt = nominal + p_fix*vel*abs(vel)
    coulomb_friction      d(eq)/dt = nominal + p_fix*sign(vel)
    periodic_disturbance  d(eq)/dt = nominal + p_fix*sin(2*pi*p_freq*t)   (p_freq starts at ``frequency_hz``)
    output_offset         measured = output state + p_fix   (a declared output ``<output>_meas``)
    input_delay           model.input_delay: delay_s (a known dead time, seconds; parameter "input_delay")
"""

from __future__ import annotations

import copy
import math

from ..synthetic import BASE

PARAM = "p_fix"
DELAY_PARAM = "input_delay"   # the name an answer gives the config's model.input_delay


def extend_config(starter: dict, system: str, family: str, frequency_hz: float = 1.0,
                  delay_s: float = 0.0) -> tuple[dict, str]:
    """A copy of ``starter`` (a config mapping) extended by ``family``; returns (config, parameter name)."""
    b = BASE[system]
    cfg = copy.deepcopy(starter)
    model = cfg["model"]
    if family == "input_delay":
        model["input_delay"] = float(delay_s)
        return cfg, DELAY_PARAM
    eq = b["states"][-1]
    params = dict(model["params"])
    free = list(model["free"])
    params[PARAM] = 0.0
    free.append(PARAM)
    terms = {"offset": "1", "cubic_stiffness": f"{b['pos']}**3", "quadratic_damping": f"{b['vel']}*abs({b['vel']})",
             "coulomb_friction": f"sign({b['vel']})"}
    if family in terms:
        model["equations"][eq] = f"({model['equations'][eq]}) + {PARAM}*{terms[family]}"
    elif family == "periodic_disturbance":
        params["p_freq"] = float(frequency_hz)
        free.append("p_freq")
        model["equations"][eq] = f"({model['equations'][eq]}) + {PARAM}*sin(2*{math.pi!r}*p_freq*t)"
    elif family == "output_offset":
        out = b["measured"]
        name = f"{out}_meas"
        model["outputs"] = {name: f"{out} + {PARAM}"}
        cfg["data"]["outputs"] = {out: name}
    else:
        raise ValueError(f"no reference extension for family {family!r}")
    model["params"], model["free"] = params, free
    return cfg, PARAM
