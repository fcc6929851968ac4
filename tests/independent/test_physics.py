"""The generator's physics against closed forms (independent of the detector's simulator)."""

import math

import numpy as np
import pytest

from pipeline.bench.independent import effects as fx
from pipeline.bench.independent.integrate import StateLimit
from pipeline.bench.independent.noise import add_noise, ar1
from pipeline.bench.independent.plant import Plant
from pipeline.bench.independent.signals import BandLimited, Delayed, Held, lfsr_bits, play_operator, prbs
from pipeline.bench.independent.systems import BASES


def msd_step(t, U, m=1.0, c=0.6, k=4.0):
    """Underdamped m x'' + c x' + k x = U from rest: x = (U/k)(1 − e^{−ζωt}(cos ω_d t + ζω/ω_d sin ω_d t))."""
    w = math.sqrt(k / m)
    z = c / (2 * math.sqrt(k * m))
    wd = w * math.sqrt(1 - z * z)
    return U / k * (1 - np.exp(-z * w * t) * (np.cos(wd * t) + z * w / wd * np.sin(wd * t)))


def test_msd_step_response_matches_the_analytic_solution():
    b = BASES["msd"]
    t = np.arange(1500) * b.dt
    X = Plant(b, Held([0.0], [1.7]), dict(b.params)).simulate(t)
    assert np.max(np.abs(X[:, 0] - msd_step(t, 1.7))) < 1e-7


def test_held_steps_are_integrated_exactly_even_between_samples():
    """First-order w' = K u − a w under piecewise-constant u: the exact solution is the discrete
    recursion w(t+s) = e^{−a s} w(t) + (K/a)(1 − e^{−a s}) u over each constant piece; switches are put
    both on and between sampling instants."""
    b = BASES["dcmotor"]
    K, a = b.params["K"], b.params["a"]
    t = np.arange(400) * b.dt
    rng = np.random.default_rng(3)
    sw = np.concatenate([[0.0], np.sort(rng.uniform(0.05, 7.9, 30))])
    sw[5] = round(sw[5] / b.dt) * b.dt                  # some exactly at a sample
    lv = rng.normal(0, 1, len(sw))
    X = Plant(b, Held(sw, lv), dict(b.params)).simulate(t)
    # exact: march through the union of switch times and sample times
    events = np.unique(np.concatenate([sw, t]))
    w, exact, tk = 0.0, {0.0: 0.0}, 0.0
    for tn in events[1:]:
        u = lv[np.searchsorted(sw, tk, side="right") - 1]
        s = tn - tk
        w = math.exp(-a * s) * w + K / a * (1 - math.exp(-a * s)) * u
        exact[tn] = w
        tk = tn
    ref = np.array([exact[x] for x in t])
    assert np.max(np.abs(X[:, 0] - ref)) < 1e-7


def test_a_delay_shifts_the_response_by_exactly_d():
    b = BASES["dcmotor"]
    d = 3.37 * b.dt                                      # not a whole number of samples
    u = Held([0.0, 0.2, 0.73, 1.31, 2.0], [0.0, 1.0, -0.5, 2.0, 0.3])   # zero before the first step
    t = np.arange(200) * b.dt
    Xd = Plant(b, Delayed(u, d), dict(b.params)).simulate(t)
    ts = t[t >= d] - d
    X0 = Plant(b, u, dict(b.params)).simulate(np.concatenate([[0.0], ts]) if ts[0] > 0 else ts)
    X0 = X0[-len(ts):]
    assert np.max(np.abs(Xd[t >= d, 0] - X0[:, 0])) < 1e-7
    assert np.all(Xd[t < d, 0] == 0.0)


def _ctx(base, U, mag=1, kind="held"):
    t = np.arange(len(U)) * base.dt
    X = np.zeros((len(U), len(base.states)))
    pilot = fx.Pilot(t, U[:, None], X, X.copy() + np.arange(len(U))[:, None], X[:, :1])
    return fx.Ctx(base, np.random.default_rng(0), mag, pilot, kind)


def test_input_saturation_clips_at_the_limit_and_the_response_is_the_clipped_step():
    b = BASES["msd"]
    U = np.linspace(-3, 3, 1001)
    eff = fx.input_saturation(_ctx(b, U))
    L = eff.params["limit"]
    assert L == pytest.approx(np.quantile(np.abs(U), fx.SAT_QUANTILE[1]))
    sig = eff.wrap_input([Held([0.0, 5.0], [10.0, -10.0])], 20.0)[0]
    tt = np.linspace(0, 10, 2001)
    vals = sig.sample(tt)[:, 0]
    assert np.max(np.abs(vals)) == pytest.approx(L)
    assert np.all(vals[tt < 5] == L) and np.all(vals[tt >= 5] == -L)
    t = np.arange(250) * b.dt
    X = Plant(b, sig, dict(b.params)).simulate(t)
    assert np.max(np.abs(X[:, 0] - msd_step(t, L))) < 1e-7


def test_dead_zone_removes_the_band_and_shifts_the_rest():
    b = BASES["msd"]
    U = np.random.default_rng(1).normal(0, 2, 5000)
    eff = fx.dead_zone(_ctx(b, U))
    w = eff.params["width"]
    assert w == pytest.approx(fx.DZ_WIDTH[1] * np.std(U))
    sig = eff.wrap_input([Held([0, 1, 2, 3], [0.5 * w, -0.9 * w, 3 * w, -2 * w])], 4.0)[0]
    assert sig.sample(np.array([0.5, 1.5, 2.5, 3.5]))[:, 0] == pytest.approx([0, 0, 2 * w, -w])


def test_tank_steady_state_is_b_u_over_a_squared():
    b = BASES["tank"]
    a, bb = b.params["a"], b.params["b"]
    t = np.arange(3001) * b.dt                          # 300 s ≫ the time constant 2√h/a ≈ 10 s
    X = Plant(b, Held([0.0], [1.3]), dict(b.params)).simulate(t)
    assert X[-1, 0] == pytest.approx((bb * 1.3 / a) ** 2, rel=1e-7)


def test_tank_overflow_holds_the_level_at_the_limit_and_releases_it():
    b = BASES["tank"]
    L = 5.0
    t = np.arange(3001) * b.dt
    u = Held([0.0, 150.0], [1.3, 0.8])                  # fills towards 6.76 > L, then drains to 2.56
    pl = Plant(b, u, dict(b.params), limit=StateLimit(0, L))
    h = pl.simulate(t)[:, 0]
    assert np.max(h) <= L + 1e-9
    held = (t > 60) & (t < 150)
    assert np.allclose(h[held], L)
    assert h[-1] == pytest.approx((0.8 / 0.5) ** 2, rel=1e-6)
    # while free it follows the unconstrained tank exactly
    free = Plant(b, u, dict(b.params)).simulate(t)[:, 0]
    first = int(np.argmax(free > L))
    assert np.max(np.abs(h[:first] - free[:first])) < 1e-7


def test_end_stop_keeps_position_and_zeroes_velocity():
    b = BASES["msd"]
    L = 0.3
    t = np.arange(600) * b.dt
    pl = Plant(b, Held([0.0, 6.0], [2.0, -2.0]), dict(b.params), limit=StateLimit(0, L, velocity=1))
    X = pl.simulate(t)
    assert np.max(X[:, 0]) <= L + 1e-9
    at = np.isclose(X[:, 0], L)
    assert at.sum() > 50 and np.all(X[at, 1] == 0.0)
    # pushed against the stop until the input reverses at t = 6 (u − k L = 0.8 > 0), then free motion
    # from (L, 0) towards −2/k: x = −0.5 + (L + 0.5) h(s), h the free response from (1, 0)
    s = t[t >= 6.0] - 6.0
    h = 1 - msd_step(s, 4.0)
    assert np.max(np.abs(X[t >= 6.0, 0] - (-0.5 + (L + 0.5) * h))) < 1e-7
    assert np.all(X[(t > 1.0) & (t < 6.0), 0] == L)


def test_multisine_has_the_requested_std_on_the_record_grid():
    rng = np.random.default_rng(0)
    s = BandLimited.make(rng, duration=40.0, cutoff=1.0, std=2.0, mean=0.5)
    u = s.sample(np.arange(2000) * 0.02)[:, 0]
    assert len(s.freqs) == 40 and s.freqs[-1] == pytest.approx(1.0)
    assert np.std(u) == pytest.approx(2.0, rel=1e-10)   # grid frequencies: cross terms vanish exactly
    assert np.mean(u) == pytest.approx(0.5, abs=1e-10)
    assert s.value(0.37)[0] == pytest.approx(s.sample(np.array([0.37]))[0, 0])


def test_prbs_is_a_maximum_length_sequence_held_at_its_clock():
    bits = lfsr_bits(2046, 0b1011001110)
    assert np.array_equal(bits[:1023], bits[1023:])       # period 2^10 − 1
    assert bits[:1023].sum() == 512                        # m-sequence balance: 2^(n−1) ones
    for p in (1, 3, 31, 341):                              # ... and no shorter period
        assert not np.array_equal(bits[:1023 - p], bits[p:1023])
    s = prbs(np.random.default_rng(0), dt=0.02, n=100, clock=5, std=2.0, mean=1.0)
    u = s.sample(np.arange(100) * 0.02)[:, 0]
    assert set(np.round(u, 12)) <= {-1.0, 3.0}
    assert np.all(u.reshape(20, 5) == u.reshape(20, 5)[:, :1])


def test_play_operator_follows_only_at_the_edges():
    y = play_operator(np.array([0.0, 0.4, 1.0, 0.8, 0.2, -1.0, -0.9]), 0.5)
    assert y == pytest.approx([0.0, 0.15, 0.75, 0.75, 0.45, -0.75, -0.75])


def test_noise_level_colour_and_tails():
    rng = np.random.default_rng(5)
    Y = np.sin(np.linspace(0, 60, 40000))[:, None]
    Yn, info = add_noise(rng, Y, 0.05, phi=0.9)
    e = (Yn - Y)[:, 0]
    assert np.std(e) == pytest.approx(0.05 * np.std(Y), rel=0.1)
    r1 = np.corrcoef(e[:-1], e[1:])[0, 1]
    assert r1 == pytest.approx(0.9, abs=0.01)
    w = ar1(np.random.default_rng(0).standard_normal(50000), 0.5)
    assert np.var(w) == pytest.approx(1.0, rel=0.03)
    Yt, _ = add_noise(np.random.default_rng(6), Y, 0.05, dist="student_t")
    et = (Yt - Y)[:, 0] / (0.05 * np.std(Y))
    assert np.var(et) == pytest.approx(1.0, rel=0.15)
    assert np.mean(et ** 4) / np.var(et) ** 2 > 6          # t(3): infinite kurtosis; Gaussian is 3
    Yh, ih = add_noise(np.random.default_rng(7), Y, 0.05, hetero=1.0)
    eh = (Yh - Y)[:, 0]
    big, small = np.abs(Y[:, 0]) > 0.9, np.abs(Y[:, 0]) < 0.1
    assert np.std(eh[big]) > 5 * np.std(eh[small])
    vm = ih["variance_model"][0]
    assert vm["a"] == pytest.approx(0.0, abs=1e-12) and vm["b"] > 0


def test_parameter_jump_changes_the_dynamics_only_after_the_jump_time():
    b = BASES["dcmotor"]
    t = np.arange(1000) * b.dt
    u = BandLimited.make(np.random.default_rng(2), duration=20.0, cutoff=1.0, std=1.0)
    pilot = fx.Pilot(t, u.sample(t), np.zeros((1000, 1)), np.zeros((1000, 1)), np.zeros((1000, 1)))
    eff = fx.parameter_jump(fx.Ctx(b, np.random.default_rng(4), 2, pilot, "band"))
    tj = eff.params["time_s"]
    pl = Plant(b, u, dict(b.params))
    eff.apply(pl)
    X1 = pl.simulate(t)
    X0 = Plant(b, u, dict(b.params)).simulate(t)
    assert np.max(np.abs(X1[t <= tj] - X0[t <= tj])) < 1e-9
    assert np.max(np.abs(X1[t > tj + 1] - X0[t > tj + 1])) > 0.05
    assert eff.params["after"] / eff.params["before"] in (pytest.approx(1.8), pytest.approx(1 / 1.8))


def test_actuator_lag_is_a_first_order_filter_of_the_input():
    """Step through u_a' = (u − u_a)/τ into w' = K u_a − a w from rest: closed form
    w = (K/a)[1 − (a e^{−t/τ} − (1/τ) e^{−a t})/(a − 1/τ)]."""
    b = BASES["dcmotor"]
    K, a = b.params["K"], b.params["a"]
    t = np.arange(300) * b.dt
    pilot = fx.Pilot(t, np.zeros((300, 1)), np.zeros((300, 1)), np.zeros((300, 1)), np.zeros((300, 1)))
    eff = fx.unmodeled_dynamics(fx.Ctx(b, np.random.default_rng(0), 1, pilot, "held"))
    tau = eff.params["time_constant_s"]
    pl = Plant(b, Held([0.0, 1e-9], [0.0, 1.0]), dict(b.params))
    eff.apply(pl)
    w = pl.simulate(t)[:, 0]
    lam = 1.0 / tau
    ref = K / a * (1 - (a * np.exp(-lam * t) - lam * np.exp(-a * t)) / (a - lam))
    assert np.max(np.abs(w - ref)) < 1e-6


def _pilot_ctx(base, kind="held", mag=1, n=1500, U=None):
    from pipeline.bench.independent.case import _inputs, _pilot
    parts = _inputs(base, kind, np.random.default_rng(0), n)
    pilot = _pilot(base, parts, np.arange(n) * base.dt)
    return fx.Ctx(base, np.random.default_rng(1), mag, pilot, kind), parts


def test_bouc_wen_state_stays_inside_its_bound_and_loops():
    b = BASES["msd"]
    ctx, parts = _pilot_ctx(b, mag=2)
    eff = fx.hysteresis(ctx)
    pl = Plant(b, parts[0], dict(b.params))
    eff.apply(pl)
    t = np.arange(1500) * b.dt
    X = pl.simulate(t)
    z = X[:, 2]
    zmax = eff.params["z_max"]
    assert np.max(np.abs(z)) <= zmax * (1 + 1e-6)
    assert np.max(np.abs(z)) > 0.8 * zmax                  # large: the hysteretic part saturates
    # a genuine loop: the restoring force is not a single-valued function of x
    f = 0.5 * 4.0 * X[:, 0] + 0.5 * 4.0 * z
    up, dn = X[:, 1] > 0, X[:, 1] < 0
    near = np.abs(X[:, 0]) < 0.05
    assert np.mean(f[near & up]) - np.mean(f[near & dn]) > 0.1


def test_extra_mode_matches_the_exact_zero_order_hold_discretisation():
    """wrong_order: the output is the base's plus a mode q'' + 2ζω q' + ω² q = g u; under held steps
    the mode's samples equal the exact ZOH discretisation (scipy.signal.cont2discrete)."""
    from scipy import signal as sps
    b = BASES["dcmotor"]
    ctx, parts = _pilot_ctx(b)
    eff = fx.wrong_order(ctx)
    om, zeta, g = eff.params["extra_mode_rad_s"], eff.params["zeta"], eff.params["gain"]
    pl = Plant(b, parts[0], dict(b.params))
    eff.apply(pl)
    t = np.arange(1500) * b.dt
    X = pl.simulate(t)
    A = np.array([[0, 1], [-om * om, -2 * zeta * om]])
    Bm = np.array([[0], [g]])
    Ad, Bd, *_ = sps.cont2discrete((A, Bm, np.eye(2), np.zeros((2, 1))), b.dt, method="zoh")
    u = parts[0].sample(t)[:, 0]
    q = np.zeros(2)
    ref = []
    for uk in u:
        ref.append(q[0])
        q = Ad @ q + Bd[:, 0] * uk
    assert np.max(np.abs(X[:, 1] - np.array(ref))) < 1e-7
    Y = pl.measure(t, X)
    assert np.allclose(Y[:, 0], X[:, 0] + X[:, 1])


def test_periodic_disturbance_sits_between_the_input_lines():
    b = BASES["msd"]
    ctx, _ = _pilot_ctx(b, kind="band")
    eff = fx.periodic_disturbance(ctx)
    fT = eff.params["frequency_hz"] * ctx.duration
    assert abs(fT - math.floor(fT) - 0.5) < 1e-9 and fT >= 10


def test_rate_limit_ramps_held_steps_at_its_rate():
    """rate_limit: behind the limiter the actuator state moves at most R per second (up to the smoothing
    τ_f's overshoot), a held step's ramp lasts |Δu|/R (checked against that closed form on the largest
    step), and the first-order dcmotor plant sees the ramp: its output differs from the unlimited one."""
    b = BASES["dcmotor"]
    ctx, parts = _pilot_ctx(b, mag=2)
    eff = fx.rate_limit(ctx)
    R = eff.params["rate"]
    pl = Plant(b, parts[0], dict(b.params))
    eff.apply(pl)
    t = np.arange(1500) * b.dt
    X = pl.simulate(t)
    ua = X[:, -1]
    assert np.max(np.abs(np.diff(ua))) <= R * b.dt * (1 + 1e-3)
    u = parts[0].sample(t)[:, 0]
    k = int(np.argmax(np.abs(np.diff(u)))) + 1          # the largest step, seen first at sample k
    du = u[k] - u[k - 1]
    m = abs(du) / (R * b.dt)                             # the ramp's length in samples
    assert m > 3 and np.all(u[k:k + int(m) + 3] == u[k])   # a long ramp, held to its end
    moves = np.abs(np.diff(ua[k - 1:k + int(m) + 3]))
    # inside the ramp the actuator moves exactly R per second, and it moves for |Δu|/R
    assert np.allclose(moves[1:int(m) - 1], R * b.dt, rtol=1e-3)
    assert abs(np.sum(moves > 0.5 * R * b.dt) - m) <= 1.0
    free = Plant(b, parts[0], dict(b.params)).simulate(t)
    assert np.max(np.abs(X[:, 0] - free[:, 0])) > 0.05 * np.std(free[:, 0])


def test_sensor_law_adds_the_cubic_to_the_measured_output_only():
    b = BASES["msd"]
    ctx, parts = _pilot_ctx(b, kind="band")
    eff = fx.sensor_law(ctx)
    pl = Plant(b, parts[0], dict(b.params))
    eff.apply(pl)
    t = np.arange(1500) * b.dt
    X = pl.simulate(t)
    free = Plant(b, parts[0], dict(b.params)).simulate(t)
    assert np.max(np.abs(X - free)) < 1e-9                 # the dynamics are untouched
    c, z0 = eff.params["c"], eff.params["centre"]
    assert np.allclose(pl.measure(t, X)[:, 0], X[:, 0] + c * (X[:, 0] - z0) ** 3, atol=1e-12)
    ratio = np.std(c * (ctx.pilot.Y[:, 0] - z0) ** 3) / np.std(ctx.pilot.Y[:, 0])
    assert ratio == pytest.approx(fx.FRAC[1], rel=1e-9)


def test_modulated_stiffness_is_the_stiffness_times_a_sine_of_three_cycles():
    """modulated_stiffness: the force equation gains −a·sin(ωt)·x, ω three cycles over the record; the
    right-hand side checked at a few points against that closed form."""
    b = BASES["msd"]
    ctx, parts = _pilot_ctx(b, kind="band")
    eff = fx.modulated_stiffness(ctx)
    assert eff.params["f_hz"] * ctx.duration == pytest.approx(3.0)
    pl = Plant(b, parts[0], dict(b.params))
    free = Plant(b, parts[0], dict(b.params))
    eff.apply(pl)
    a, om = eff.params["a"], 2 * math.pi * eff.params["f_hz"]
    for tt, x in [(0.3, np.array([0.2, -0.1])), (7.1, np.array([-0.5, 0.4]))]:
        d = pl.rhs(tt, x) - free.rhs(tt, x)
        assert d[b.index(b.pos)] == 0.0
        assert d[b.index(b.force_eq)] == pytest.approx(-a * math.sin(om * tt) * x[b.index(b.pos)], rel=1e-12)
