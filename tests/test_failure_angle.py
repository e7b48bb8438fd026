"""The failure angle beta* (eq 14) and the continuity of the forces on down-slopes (issue #13, item 2)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from wheelloader.estimator import (
    PAPER_BOUNDS,
    Bucket,
    ContactState,
    ModelOptions,
    Pile,
    SoilParams,
    bezier_path,
    contact_state,
    preset,
    soil_forces,
)
from wheelloader.estimator.failure_angle import (
    BETA_AT_EPS1,
    BETA_AT_RHO_LIMIT,
    BETA_AT_SLOPE_LIMIT,
    BETA_INTERIOR,
    beta_bounds,
    cold_start,
    optimal_beta,
    optimal_beta_scalar,
)
from wheelloader.estimator.force_model import bearing_factors, soil_forces_single
from wheelloader.estimator.validity import FLAG_ALPHA_CLAMPED, alpha_lower_limit, clamp_angles

deg = math.radians

soils = st.builds(
    SoilParams,
    gamma=st.floats(*PAPER_BOUNDS["gamma"]),
    cohesion=st.floats(*PAPER_BOUNDS["cohesion"]),
    adhesion=st.floats(*PAPER_BOUNDS["adhesion"]),
    phi=st.floats(*PAPER_BOUNDS["phi"]),
    delta=st.floats(*PAPER_BOUNDS["delta"]),
    k_c=st.floats(*PAPER_BOUNDS["k_c"]),
    k_phi=st.floats(*PAPER_BOUNDS["k_phi"]),
    n=st.floats(*PAPER_BOUNDS["n"]),
)
#: A point (depth [m], rho [rad], alpha [rad]) of the whole pose box, alpha in [-60, 60] deg.
poses = st.tuples(st.floats(0.0, 0.6), st.floats(deg(0.0), deg(170.0)), st.floats(deg(-60.0), deg(60.0)))


def test_regression_issue_13_down_slope_jump():
    """The two slopes of issue #13 (item 2) 2e-16 rad apart gave 17 kN / 28 kN and 86 kN / 242 kN."""
    soil, bucket = preset("lean_clay"), Bucket()
    a, b = (soil_forces_single(soil, 0.3, 0.0, alpha, bucket.floor_length, 0.0, bucket)
            for alpha in (-0.6095792035438609, -0.6095792035438607))
    assert a[0] == pytest.approx(b[0], rel=1e-9) and a[1] == pytest.approx(b[1], rel=1e-9)
    assert a[2] == pytest.approx(b[2], abs=1e-9)
    assert a[3] & FLAG_ALPHA_CLAMPED  # -34.9 deg is steeper than phi - 5 deg = 22 deg


def _line_forces(soil, p0, p1, t):
    bucket = Bucket()
    p = np.asarray(p0)[None, :] + np.asarray(t)[:, None] * (np.asarray(p1) - np.asarray(p0))[None, :]
    depth, rho, alpha = p[:, 0], p[:, 1], p[:, 2]
    blade = np.minimum(depth / np.maximum(np.sin(rho), 0.1), bucket.floor_length)
    state = ContactState(depth, rho, alpha, blade, np.full(len(t), 0.05))
    out = soil_forces(soil, state, bucket)
    no_bekker = out.tangential - bucket.width * bucket.edge_thickness * out.pressure
    return np.stack([out.fee_force, no_bekker, out.normal])


@settings(max_examples=150, deadline=None)
@given(soil=soils, p0=poses, p1=poses)
def test_no_jump_along_straight_lines_in_depth_rho_alpha(soil, p0, p1):
    """Along any straight line in (depth, rho, alpha) over the whole box the forces are continuous.

    The interval of the largest step of 600 samples is cut to its steepest quarter 25 times (to 1e-15 of
    the step): a continuous function's step vanishes with the interval, a jump keeps its size. F_T is
    checked without the Bekker term, whose d^n is Hoelder-continuous only and is continuous in depth anyway.
    """
    t = np.linspace(0.0, 1.0, 600)
    forces = _line_forces(soil, p0, p1, t)
    scale = max(float(np.max(np.abs(forces))), 1.0)
    for row in range(forces.shape[0]):
        k = int(np.argmax(np.abs(np.diff(forces[row]))))
        step = _refined_step(lambda tt: _line_forces(soil, p0, p1, tt)[row], t[k], t[k + 1])  # noqa: B023
        assert step <= 1e-6 * scale, row


#: A carved profile whose down-slopes (-41 deg, then -8 deg) are steeper than some soils' friction angle.
CARVED = Pile.from_polyline([-0.5, 0.0, 0.35, 0.7, 1.4, 3.0, 3.5], [0.0, 0.0, 0.5, 0.2, 0.1, 1.3, 1.3])


def _refined_step(fn, a: float, b: float, halvings: int = 25) -> float:
    """Largest step of ``fn`` left after cutting ``[a, b]`` to the quarter with its largest step ``halvings`` times."""
    for _ in range(halvings):
        tt = np.linspace(a, b, 5)
        step = np.abs(np.diff(fn(tt)))
        k = int(np.argmax(step))
        a, b = tt[k], tt[k + 1]
    return float(step[k])


@settings(max_examples=40, deadline=None)
@given(soil=soils, seed=st.integers(0, 10_000))
def test_no_jump_along_paths_through_a_carved_pile(soil, seed):
    """Paths through down-slopes: between any two 600 Hz samples the forces have no jump.

    Near ``alpha = -phi + 5 deg`` with ``rho + delta`` close to ``pi/2 - 2 phi`` beta* is steep (it can cross
    its branch within about a degree of slope), so a 60 Hz vs 600 Hz shrink test cannot tell steep from
    broken there; instead the largest 600 Hz step is refined along the segment between the two contact
    states (kinematics is continuous, ``tests/test_kinematics.py``) until it vanishes.
    """
    rng = np.random.default_rng(seed)
    control = (rng.uniform(0.6, 1.3), rng.uniform(0.0, 0.2))
    end = (control[0] + rng.uniform(0.15, 0.4), 1.2)
    path = bezier_path((-0.1, 0.03), control, end, rate=600.0, curl_from=rng.uniform(0.4, 0.7),
                       angle_end=rng.uniform(0.5, 0.9))
    bucket = Bucket()
    state = contact_state(path.x, path.z, path.blade_angle, CARVED, bucket)
    out = soil_forces(soil, state, bucket)
    k = int(np.argmax(np.abs(np.diff(out.fee_force))))
    fields = [np.asarray(getattr(state, name), dtype=float)[k:k + 2]
              for name in ("depth", "rho", "alpha", "blade_length", "fill_volume")]

    def fee(t):
        at = [f[0] + t * (f[1] - f[0]) for f in fields]
        return soil_forces(soil, ContactState(*at), bucket).fee_force

    assert _refined_step(fee, 0.0, 1.0) <= 1e-6 * max(float(np.max(out.fee_force)), 1.0)


def test_down_slope_lines_that_jumped_are_continuous():
    """The issue's experiment (random soil and pose lines with alpha < 0; 401 of 3 000 jumped): no jump left."""
    rng = np.random.default_rng(13)
    t = np.linspace(0.0, 1.0, 60)
    for _ in range(300):
        soil = SoilParams(**{name: rng.uniform(*bound) for name, bound in PAPER_BOUNDS.items()})
        p0 = (rng.uniform(0.01, 0.6), rng.uniform(deg(10), deg(150)), rng.uniform(deg(-60), 0.0))
        p1 = (rng.uniform(0.01, 0.6), rng.uniform(deg(10), deg(150)), rng.uniform(deg(-60), 0.0))
        fee = _line_forces(soil, p0, p1, t)[0]
        k = int(np.argmax(np.abs(np.diff(fee))))
        step = _refined_step(lambda tt: _line_forces(soil, p0, p1, tt)[0], t[k], t[k + 1])  # noqa: B023
        assert step <= 1e-6 * max(float(np.max(fee)), 1.0)


@settings(max_examples=300, deadline=None)
@given(phi=st.floats(*PAPER_BOUNDS["phi"]), delta=st.floats(*PAPER_BOUNDS["delta"]),
       u=st.floats(0.0, 1.0), v=st.floats(0.0, 1.0))
def test_n_gamma_is_unimodal_on_the_valid_branch(phi, delta, u, v):
    """On the branch of clamped angles N_gamma falls then rises (at most one sign change of its slope)."""
    opts = ModelOptions()
    alpha_lo = float(alpha_lower_limit(phi, opts))
    alpha = alpha_lo + u * (opts.alpha_max - alpha_lo)
    rho_hi = math.pi - opts.eps1 - opts.eps2 - delta - phi
    rho = opts.rho_min + v * (rho_hi - opts.rho_min)
    lo, hi = beta_bounds(np.array([alpha]), np.array([rho]), phi, delta, opts)
    beta = np.linspace(lo[0], hi[0], 2001)
    n_gamma = bearing_factors(alpha, rho, beta, phi, delta)[0]
    assert np.all(n_gamma >= -1e-12) and np.all(np.isfinite(n_gamma))
    step = np.diff(n_gamma)
    step = step[np.abs(step) > 1e-12 * max(1.0, float(np.max(np.abs(n_gamma))))]
    signs = np.sign(step)
    runs = [int(s) for k, s in enumerate(signs) if k == 0 or s != signs[k - 1]]
    assert runs in ([], [-1], [1], [-1, 1]), runs  # falls, rises, or falls then rises
    best = float(optimal_beta(np.array([alpha]), np.array([rho]), phi, delta, opts)[0])
    k = int(np.argmin(n_gamma))
    assert bearing_factors(alpha, rho, best, phi, delta)[0] <= n_gamma[k] + 1e-9


def test_scalar_vector_and_where_codes_agree():
    rng = np.random.default_rng(5)
    phi = rng.uniform(0.0, deg(45), 2000)
    delta = rng.uniform(0.0, deg(45), 2000)
    alpha, rho, _ = clamp_angles(rng.uniform(deg(-60), deg(60), 2000), rng.uniform(0.0, 3.0, 2000), phi, delta)
    beta, where = optimal_beta(alpha, rho, phi, delta, return_where=True)
    lo, hi = beta_bounds(alpha, rho, phi, delta)
    assert np.all((beta >= lo - 1e-12) & (beta <= hi + 1e-12))
    assert set(np.unique(where)) <= {BETA_INTERIOR, BETA_AT_EPS1, BETA_AT_RHO_LIMIT, BETA_AT_SLOPE_LIMIT}
    assert np.allclose(beta[where == BETA_AT_EPS1], lo[where == BETA_AT_EPS1])
    assert np.allclose(beta[where == BETA_AT_SLOPE_LIMIT], 0.5 * math.pi - alpha[where == BETA_AT_SLOPE_LIMIT])
    for i in range(0, 2000, 37):
        assert optimal_beta_scalar(alpha[i], rho[i], phi[i], delta[i]) == pytest.approx(beta[i], abs=1e-9)


def test_down_slopes_are_clamped_at_the_friction_angle_less_the_margin():
    soil, opts = preset("gravel"), ModelOptions()
    limit = -(soil.phi - opts.slope_margin)
    alpha, _, flags = clamp_angles(np.array([limit - 0.1, limit + 0.1, deg(-70)]), np.full(3, 0.8), soil.phi,
                                   soil.delta)
    assert alpha[0] == pytest.approx(limit) and alpha[1] == pytest.approx(limit + 0.1) and alpha[2] == limit
    assert flags[0] == FLAG_ALPHA_CLAMPED and flags[1] == 0
    # frictionless soil: flat ground lies below the limit and counts as a 5 deg up-slope (flagged)
    alpha, _, flags = clamp_angles(np.array([0.0]), np.array([0.8]), 0.0, 0.0)
    assert alpha[0] == pytest.approx(opts.slope_margin) and flags[0] == FLAG_ALPHA_CLAMPED


@pytest.mark.parametrize("name", ["gravel", "lean_clay", "fat_clay"])
def test_casadi_model_agrees_on_down_slopes(name):
    """The planner's CasADi model (smooth clamps, unrolled beta*) follows the same branch for alpha < 0."""
    casadi_model = pytest.importorskip("wheelloader.planner.casadi_model")
    soil, bucket = preset(name), Bucket()
    alpha = np.linspace(deg(-50), deg(10), 61)
    rho = np.full_like(alpha, deg(45))
    depth = np.full_like(alpha, 0.25)
    state = ContactState(depth, rho, alpha, np.minimum(depth / np.sin(rho), bucket.floor_length), np.zeros_like(alpha))
    ref = soil_forces(soil, state, bucket)
    vec = casadi_model.soil_vector(soil, bucket)
    got = [casadi_model.casadi_forces(vec, d / math.cos(a), r, a, 0.0, bucket)
           for d, r, a in zip(depth, rho, alpha, strict=True)]
    f_n = np.array([float(g["F_N"]) for g in got])
    # away from the smooth clamp's 1e-3 rad corner the two agree closely
    far = np.abs(alpha - alpha_lower_limit(soil.phi)) > 0.02
    assert np.max(np.abs(f_n - ref.normal)[far]) <= 0.03 * np.max(ref.normal)


@pytest.mark.parametrize("per_sample_phi", [False, True])
@pytest.mark.parametrize("warm", [False, True])
def test_newton_tail_on_floats_gives_the_array_iterates(monkeypatch, per_sample_phi, warm):
    """The last unconverged samples, finished on Python floats, end where the NumPy loop ends, bit for bit."""
    import wheelloader.estimator.failure_angle as fa

    rng = np.random.default_rng(11)
    n = 400
    phi = rng.uniform(deg(20), deg(45), n) if per_sample_phi else deg(35)
    delta = deg(25)
    alpha, rho, _ = clamp_angles(rng.uniform(deg(-40), deg(50), n), rng.uniform(0.0, 2.5, n), phi, delta)
    guess = rng.uniform(0.05, 1.2, n) if warm else None
    results = []
    for tail in (0, 1, 16, n):  # 0: the NumPy loop only; n: the floats from the first step
        monkeypatch.setattr(fa, "_TAIL", tail)
        results.append(optimal_beta(alpha, rho, phi, delta, guess=guess))
    _, where = optimal_beta(alpha, rho, phi, delta, guess=guess, return_where=True)
    assert np.count_nonzero(where == BETA_INTERIOR) > 20  # the Newton loop runs
    for other in results[1:]:
        np.testing.assert_array_equal(other, results[0])


@pytest.mark.parametrize("name", ["gravel", "sand", "dirt", "lean_clay"])
def test_cold_start_reaches_the_root_in_three_steps_on_pile_faces(name):
    """Rows entering a pile face (slope 10-40 deg, blade 20-60 deg) have no warm guess: from the explicit cold start
    three Halley steps give beta* to rounding (the batched env's entering rows started 0.43 rad off in the middle of
    the branch and took up to 14 Newton steps)."""
    soil = preset(name)
    a, r = np.meshgrid(np.linspace(deg(10), deg(40), 31), np.linspace(deg(20), deg(60), 41))
    alpha, rho, _ = clamp_angles(a.ravel(), r.ravel(), soil.phi, soil.delta)
    beta, where = optimal_beta(alpha, rho, soil.phi, soil.delta, return_where=True)
    inner = where == BETA_INTERIOR
    assert np.count_nonzero(inner) >= 10
    three = optimal_beta(alpha, rho, soil.phi, soil.delta, max_iter=3)
    assert np.max(np.abs(three - beta)[inner]) <= 1e-14
    lo, hi = beta_bounds(alpha, rho, soil.phi, soil.delta)
    b_hi = -np.tan(alpha + hi) + 1.0 / np.tan(alpha + hi + soil.phi)
    start = cold_start(b_hi, 1.0 / np.tan(rho + soil.delta + soil.phi))
    assert np.median(np.abs(start - beta)[inner]) <= 0.5 * np.median(np.abs(0.5 * (lo + hi) - beta)[inner])


@settings(max_examples=300, deadline=None)
@given(b_hi=st.floats(-1e6, 1e6), s=st.floats(1e-3, math.pi - 1e-3))
def test_cold_start_lies_on_the_branch_side_of_the_pole(b_hi, s):
    """The quadratic's larger root is an angle in (0, pi - s): never beyond the pole of cot(beta + s)."""
    start = float(cold_start(b_hi, 1.0 / math.tan(s)))
    assert 0.0 <= start <= math.pi - s + 1e-12
