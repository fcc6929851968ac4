"""A continuous-time estimate simulated by the pipeline's kernel matches scipy.signal.lsim."""

import numpy as np
import pytest
from scipy import signal

from pipeline.ct.to_model import transfer_function_model
from pipeline.errors import InputError
from pipeline.simulate import simulate_outputs


@pytest.mark.parametrize("num,den", [([1.25], [0.25, 0.7, 1.0]), ([-0.1, 1.25], [0.25, 0.7, 1.0]),
                                     ([2.0], [1.0, 3.0]), ([1.0, 0.5, 2.0], [1.0, 2.0, 3.0, 1.0])])
def test_kernel_simulation_matches_lsim(num, den):
    t = np.arange(0, 20, 0.01)
    u = np.sin(1.3 * t) + 0.5 * np.sign(np.sin(0.4 * t))
    m = transfer_function_model(num, den, intersample="foh", substeps=2)
    y = simulate_outputs(m, t, u[:, None], np.zeros(len(m.states)), ["y"])[:, 0]
    _, ref, _ = signal.lsim((num, den), u, t, interp=True)
    np.testing.assert_allclose(y, ref, atol=1e-6 * max(1, np.max(np.abs(ref))))


def test_tsang_billings_s1_estimate_becomes_a_simulable_model():
    """S1 (0.25 y'' + 0.7 y' + y = 1.25 u): identify_ct's num/den simulate like the true system."""
    from pipeline.ct import identify_ct
    from tests.ct._tb_systems import H, simulate
    t, u, y = simulate("S1")
    est = identify_ct(u, y, H, 2, threshold=None, m_max=14)
    m = transfer_function_model(est.num, est.den, intersample="foh", substeps=4)
    tt = np.arange(len(u)) * H
    yh = simulate_outputs(m, tt, u[:, None], np.zeros(2), ["y"])[:, 0]
    _, ref, _ = signal.lsim(([1.25], [0.25, 0.7, 1.0]), u, tt, interp=True)
    assert np.sqrt(np.mean((yh - ref) ** 2)) < 0.01 * np.std(ref)


def test_improper_transfer_function_is_bad_input():
    with pytest.raises(InputError, match="numerator degree"):
        transfer_function_model([1.0, 0.0], [1.0, 1.0])
