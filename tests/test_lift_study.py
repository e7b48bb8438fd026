"""``benchmarks/lift_study.py``: the tie of the lift coefficient to path features, and the tied form's fit."""

import math
from pathlib import Path

import numpy as np
from benchmark_scripts import load_benchmark

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT / "data" / "mpm" / "sand_path1.csv"


def test_tie_recovers_a_linear_dependence_and_clips_at_zero():
    ls = load_benchmark("lift_study")
    rng = np.random.default_rng(3)
    x = rng.uniform(0.0, 1.0, size=(40, len(ls.FEATURES)))
    c = 2.0 - 3.0 * x[:, 1] + 0.5 * x[:, 3]
    tie = ls.fit_tie(x, c, (1, 3))
    np.testing.assert_allclose(tie.coef, [2.0, -3.0, 0.5], atol=1e-9)
    assert tie(np.array([0.0, 1.0, 0.0, 0.0, 0.0])) == 0.0  # 2 - 3 < 0: clipped
    assert ls.fit_tie(x, c, ()).coef.shape == (1,)


def test_tied_lift_is_the_free_lift_with_its_coefficient_tied_to_gamma():
    """The tied form's F_T equals model_form's ``+ lift`` with the lift coefficient set to gamma * c; a path's
    features are dimensionless and finite; the tied fit recovers forces it can express."""
    ls = load_benchmark("lift_study")
    mf = ls.mf
    case = ls.load_cases([str(LOG)], mf.DEFAULT_PAYLOAD)[0]
    assert case.features.shape == (len(ls.FEATURES),) and np.all(np.isfinite(case.features))
    assert 0.0 < case.features[0] < 2.0  # d_max / L
    tie = ls.TiedLift((), np.array([1.7]))
    phi, delta, n = math.radians(35.0), math.radians(15.0), 1.53
    tied_t, tied_n = ls.tied_columns(tie, offset=False)(case, phi, delta, n, ())
    free_t, free_n = mf.columns(case, phi, delta, n, ("lift",))
    x = np.array([1500.0, 800.0, 0.0, 4.0e5])
    np.testing.assert_allclose(tied_t @ x, free_t @ np.append(x, 1.7 * 1500.0), rtol=1e-12)
    np.testing.assert_allclose(tied_n @ x, free_n @ np.append(x, 1.7 * 1500.0), rtol=1e-12)
    case.y_t, case.y_n = tied_t @ x, tied_n @ x
    case.obs_r = np.hypot(case.y_t, case.y_n)
    fit = ls.fit_with(ls.tied_columns(tie, offset=False), [case], np.radians([20.0, 35.0]), (1.0, 1.53))
    assert (round(math.degrees(fit["phi"])), fit["n"]) == (35, 1.53)
    assert ls.error_with(ls.tied_columns(tie, offset=False), case, fit) < 1e-6
