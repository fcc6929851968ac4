"""An independent record generator for calibrating the diagnosis (issue 9).

It shares no code with the detector: it imports numpy, scipy, pandas, yaml and its own modules only
(``tests/independent/test_independence.py`` scans the ASTs). Plants are integrated with
``scipy.integrate.solve_ivp`` on continuous-time inputs; effects are written out as plain Python.

    from pipeline.bench.independent import make_case, menu
    case = make_case("cubic_stiffness", "msd", seed=0, magnitude="medium", noise=0.02,
                     colour="white", input_kind="band", n=2000, out_dir="cases")
"""

from .case import COLOURS, INPUT_KINDS, NOISE_LEVELS, Case, make_case, menu
from .effects import MAGNITUDES, OUT_OF_VOCABULARY, SUPPORTED
from .systems import BASES

__all__ = ["BASES", "COLOURS", "Case", "INPUT_KINDS", "MAGNITUDES", "NOISE_LEVELS", "OUT_OF_VOCABULARY",
           "SUPPORTED", "make_case", "menu"]
