"""The failure angle beta* of the FEE (eq 14): one solver, used by every backend.

beta* minimises N_gamma (eq 10) on the valid branch

    eps1 <= beta <= min(pi - (rho + delta + phi) - eps2, pi/2 - alpha)

for angles clamped into the validity domain (:func:`~wheelloader.estimator.validity.clamp_angles`,
which keeps ``alpha >= slope_margin - phi``). On that branch ``sin(alpha + beta + phi) > 0``, so N_gamma, N_c and
N_q are non-negative and finite, and N_gamma is unimodal (checked on a grid of 1 000 angles for 10^5
random configurations over the whole parameter box, ``tests/test_force_model.py`` checks it by
hypothesis): beta* is the unique root of ``d ln N_gamma / d beta`` (:func:`log_ngamma_slope`) or a
bound, and it moves continuously with the angles. At ``beta = pi/2 - alpha`` N_gamma = 0.

Three front ends share the branch and the slope:

* :func:`optimal_beta`: NumPy arrays, safeguarded Halley iteration inside a bisection bracket (forces, fits);
* :func:`optimal_beta_scalar`: one sample in pure ``math`` (environment steps), the same iteration;
* :func:`unrolled_beta`: a fixed number of guarded Newton steps for symbolic backends (the
  planner's CasADi model passes ``casadi.tan`` and smooth clamps).

The first two start from a warm guess where one is given and inside the bracket, else from
:func:`cold_start`, an explicit approximate root. Each step is Halley's (the slope, its derivative and its second
derivative come from the same four tangents, :func:`log_ngamma_derivatives`), kept where it lands inside the
bracket, else a bisection; a sample stops once its step is shorter than ``tol`` (1e-11 rad), so beta* is the
root to rounding whatever the start. On the batched env's own calls (1024 envs) rows entering the soil took 9-14
Newton steps from the middle of the branch (3-8 of them bisections) and warm rows 4-6; from the cold start with
Halley steps both take 3-4.

The opt-in rule of the least weight force is :mod:`~wheelloader.estimator.failure_angle_weight`.
"""

from __future__ import annotations

import math

import numpy as np

from .validity import DEFAULT_OPTIONS, ModelOptions

#: ``where`` code of :func:`optimal_beta`: beta* is an interior root of d ln N_gamma / d beta.
BETA_INTERIOR = 0
#: ``where`` code: beta* is on the lower bound eps1.
BETA_AT_EPS1 = 1
#: ``where`` code: beta* is on the upper bound ``pi - (rho + delta + phi) - eps2``.
BETA_AT_RHO_LIMIT = 2
#: ``where`` code: beta* is on the upper bound ``pi/2 - alpha`` (N_gamma = 0 there).
BETA_AT_SLOPE_LIMIT = 3


def beta_bounds(alpha, rho, phi, delta, options: ModelOptions = DEFAULT_OPTIONS, minimum=np.minimum):
    """Valid branch ``(lo, hi)`` of beta for clamped angles (module docstring).

    ``minimum`` is the array library's element-wise minimum (the CasADi model passes a smooth one);
    with NumPy both bounds are arrays of the broadcast shape.
    """
    hi = minimum(math.pi - (rho + delta + phi) - options.eps2, 0.5 * math.pi - alpha)
    lo = np.full_like(hi, options.eps1) if isinstance(hi, np.ndarray) else options.eps1
    return lo, hi


def of_shape(v, shape: tuple[int, ...]) -> np.ndarray:
    """``v`` as an array of ``shape`` (read only): ``v`` itself where it already is one (the batched env's case,
    without :func:`numpy.broadcast_to`'s cost per call), else a broadcast view; the same values either way."""
    if type(v) is np.ndarray and v.shape == shape:
        return v
    return np.broadcast_to(v, shape)


def log_ngamma_slope(beta, alpha, phi, s, tan=np.tan):
    """``g = d ln N_gamma / d beta`` and ``dg / d beta`` (eq 10), with ``s = rho + delta + phi``.

    ``tan`` is the tangent of the array library (NumPy by default; ``math.tan`` for scalars,
    ``casadi.tan`` for the planner's symbolic Newton steps)."""
    t1 = tan(alpha + beta)
    c2 = 1.0 / tan(alpha + beta + phi)
    c3 = 1.0 / tan(beta)
    c4 = 1.0 / tan(beta + s)
    g = -t1 + c2 - c3 - c4
    dg = -t1 * t1 - c2 * c2 + c3 * c3 + c4 * c4
    return g, dg


def log_ngamma_derivatives(beta, alpha, phi, s, tan=np.tan):
    """:func:`log_ngamma_slope`'s ``g`` and ``dg`` and half the second derivative, ``d2g / 2`` (eq 10).

    With ``t1 = tan(alpha + beta)`` and ``c2, c3, c4`` the cotangents of :func:`log_ngamma_slope`,
    ``d2g / 2 = -t1 (1 + t1^2) + c2 (1 + c2^2) - c3 (1 + c3^2) - c4 (1 + c4^2)``. The reference form of the
    solvers' Halley step (:func:`halley_step`)."""
    g, dg = log_ngamma_slope(beta, alpha, phi, s, tan)
    t1 = tan(alpha + beta)
    c2 = 1.0 / tan(alpha + beta + phi)
    c3 = 1.0 / tan(beta)
    c4 = 1.0 / tan(beta + s)
    half = (c2 * c2 + 1.0) * c2 - (t1 * t1 + 1.0) * t1 - (c3 * c3 + 1.0) * c3 - (c4 * c4 + 1.0) * c4
    return g, dg, half


def halley_step(x: float, g: float, dg: float, half: float, a: float, b: float) -> float:
    """The solvers' next iterate from ``x`` (scalar reference form): Halley's step
    ``x - n / (1 - n half / dg)`` with ``n = g / dg`` where ``dg > 0``, its factor is positive and it lands in
    the bracket ``[a, b]`` (already updated with ``x``), else the bracket's middle."""
    if dg > 0.0:
        n = g / dg
        fac = 1.0 - n * (half / dg)
        if fac > 0.0:
            new = x - n / fac
            if a <= new <= b:
                return new
    return 0.5 * (a + b)


def cold_start(b_hi, cot_s, sqrt=np.sqrt, atan2=np.arctan2):
    """Explicit approximate root of ``g`` (:func:`log_ngamma_slope`), the solvers' start without a warm guess.

    ``g = B(beta) - cot(beta) - cot(beta + s)`` with ``B = -tan(alpha + beta) + cot(alpha + beta + phi)``.
    An interior root lies only where the upper bound is the rho limit ``pi - s - eps2``, near the pole of
    ``-cot(beta + s)``; there ``B`` varies slowly. With ``B`` frozen at its value at the upper bound
    (``b_hi``, which the bracket check has just evaluated), ``cot(beta) + cot(beta + s) = B`` is a quadratic in
    ``c = cot(beta)``: ``c^2 + (2k - B) c - (1 + B k) = 0`` with ``k = cot(s)`` (``cot_s``). Its discriminant
    is ``B^2 + 4 k^2 + 4 > 0``, and its larger root is the one with ``beta`` in ``(0, pi - s)``:
    ``beta0 = atan2(2, sqrt(B^2 + 4 k^2 + 4) - (2k - B))``. The callers use it where it lies strictly inside
    the bracket (else the bracket's middle; a NaN from a pole is not inside). Measured on the batched env's rows
    entering the soil: 8e-3 rad from the root (median), against 0.43 rad for the middle of the branch.
    ``sqrt``, ``atan2``: the array library's (``math``'s for scalars)."""
    return atan2(2.0, sqrt(b_hi * b_hi + 4.0 * cot_s * cot_s + 4.0) - (2.0 * cot_s - b_hi))


def optimal_beta(alpha, rho, phi, delta, options: ModelOptions = DEFAULT_OPTIONS,
                 tol: float = 1e-11, max_iter: int = 60, guess=None, return_where: bool = False):
    """Failure angle beta* minimising N_gamma (eq 10) under eq 14, on the valid branch.

    Parameters
    ----------
    alpha, rho : array_like
        Slope and blade angle [rad], already clamped (:func:`~wheelloader.estimator.validity.clamp_angles`).
    phi, delta : float or array_like
        Friction angles [rad]; scalars or one per sample (a batch of environments). All inputs broadcast.
    options : ModelOptions
        Margins eps1, eps2.
    tol : float
        Step size [rad] below which the iteration stops.
    max_iter : int
        Largest number of iterations.
    guess : array_like, optional
        Warm start (e.g. the previous step's beta*), used where it lies inside the bracket; elsewhere
        :func:`cold_start`.
    return_where : bool
        Also return where beta* lies (``BETA_*`` codes).

    Returns
    -------
    numpy.ndarray or tuple
        beta* [rad]; with ``return_where`` also the ``BETA_*`` code per sample.
    """
    if (type(alpha) is np.ndarray and type(rho) is np.ndarray and alpha.ndim == 1 and alpha.shape == rho.shape
            and alpha.dtype == rho.dtype == np.float64 and type(phi) is float and type(delta) is float):
        shape = alpha.shape  # the batched env's case: one soil, 1-d angles (no broadcasting to do)
    else:
        arrays = np.broadcast_arrays(*(np.asarray(v, dtype=float) for v in (alpha, rho, phi, delta)))
        shape = arrays[0].shape  # 0-d inputs are worked on as 1-d and given back in their shape
        alpha, rho, phi, delta = (np.ravel(v) for v in arrays)
    with np.errstate(divide="ignore", invalid="ignore"):  # the slopes' cotangents and the steps divide
        return _optimal_beta(alpha, rho, phi, delta, shape, options, tol, max_iter, guess, return_where)


def _optimal_beta(alpha, rho, phi, delta, shape, options, tol, max_iter, guess, return_where):
    """:func:`optimal_beta` on 1-d arrays (floating-point errors already silenced)."""
    s = rho + delta + phi
    lo, hi = (of_shape(v, alpha.shape) for v in beta_bounds(alpha, rho, phi, delta, options))
    m = alpha.size
    if isinstance(phi, np.ndarray):
        g_lo, g_hi = _slope_only(lo, alpha, phi, s), _slope_only(hi, alpha, phi, s)
    else:  # both ends in one evaluation (element-wise, so the same values)
        both = _slope_only(np.concatenate((lo, hi)), np.concatenate((alpha, alpha)), phi, np.concatenate((s, s)))
        g_lo, g_hi = both[:m], both[m:]
    at_lo = g_lo >= 0.0
    at_hi = (g_hi <= 0.0) & ~at_lo
    inner = ~(at_lo | at_hi)
    beta = np.where(at_lo, lo, hi)  # a new array
    if inner.any():
        a, b, al, ss = lo[inner], hi[inner], alpha[inner], s[inner]
        ph = phi[inner] if isinstance(phi, np.ndarray) else phi
        if guess is None:
            x = _cold_starts(a, b, al, ph, ss)
        else:
            g0 = of_shape(np.asarray(guess, dtype=float), alpha.shape)[inner]
            warm = (g0 > a) & (g0 < b)
            x = g0 if warm.all() else np.where(warm, g0, _cold_starts(a, b, al, ph, ss))
        beta[inner] = _bracketed_newton(x, a, b, al, ph, ss, tol, max_iter)
    if not return_where:
        return beta.reshape(shape)
    at_rho_limit = (math.pi - s - options.eps2) <= (0.5 * math.pi - alpha)
    where = np.where(at_lo, BETA_AT_EPS1,
                     np.where(at_hi, np.where(at_rho_limit, BETA_AT_RHO_LIMIT, BETA_AT_SLOPE_LIMIT), BETA_INTERIOR))
    return beta.reshape(shape), where.reshape(shape)


#: At most this many unconverged samples :func:`_bracketed_newton` finishes on floats (:func:`_newton_tail`).
_TAIL = 16


def _cold_starts(a, b, al, ph, ss) -> np.ndarray:
    """:func:`cold_start` for arrays where it lies inside ``(a, b)``, else the bracket's middle (``b`` is the upper
    bound)."""
    t = np.empty((3, a.size))
    np.add(al, b, out=t[0])  # alpha + hi
    np.add(t[0], ph, out=t[1])  # alpha + hi + phi
    t[2] = ss
    np.tan(t, out=t)
    np.divide(1.0, t[1:], out=t[1:])  # cot(alpha + hi + phi), cot(s)
    x = cold_start(t[1] - t[0], t[2])
    mid = a + b
    mid *= 0.5
    return np.where((x > a) & (x < b), x, mid)


def _slope_only(beta, alpha, phi, s):
    """``g`` of :func:`log_ngamma_slope` (the same operations in the same order, so the same values), with
    the four tangents in one ``np.tan`` call."""
    t = np.empty((4, beta.size))
    np.add(alpha, beta, out=t[0])
    np.add(t[0], phi, out=t[1])
    t[2] = beta
    np.add(beta, s, out=t[3])
    np.tan(t, out=t)
    np.divide(1.0, t[1:], out=t[1:])
    g = t[1] - t[0]  # -t1 + c2
    g -= t[2]
    g -= t[3]
    return g


def _bracketed_newton(x, a, b, al, ph, ss, tol: float, max_iter: int) -> np.ndarray:
    """:func:`optimal_beta`'s safeguarded Halley iteration on the interior samples, from ``x`` inside ``(a, b)``.

    Each sample follows its own sequence of iterates (element-wise operations only): it stops once a step is
    shorter than ``tol`` or after ``max_iter`` steps. Its steps are :func:`halley_step`'s on
    :func:`log_ngamma_derivatives`, with the same roundings (``-t1 + c2`` computed as ``c2 - t1``,
    ``-t1*t1 - c2*c2`` as ``-(t1*t1 + c2*c2)``). Only the unconverged samples are iterated; the last few go through
    :func:`_newton_tail`, which gives the same iterates bit for bit. Called with floating-point errors silenced
    (:func:`optimal_beta`)."""
    out = np.empty_like(x)
    active = np.arange(x.size)
    per_sample_phi = isinstance(ph, np.ndarray)
    it = 0
    while it < max_iter:
        k = x.size
        if k <= _TAIL:  # a NumPy iteration costs about 30 array calls whatever the samples' number
            out[active] = _newton_tail(x.tolist(), a.tolist(), b.tolist(), al.tolist(),
                                       ph.tolist() if per_sample_phi else [ph] * k, ss.tolist(), tol, max_iter - it)
            return out
        t = np.empty((4, k))
        np.add(al, x, out=t[0])  # alpha + beta
        np.add(t[0], ph, out=t[1])  # alpha + beta + phi
        t[2] = x
        np.add(x, ss, out=t[3])  # beta + s
        np.tan(t, out=t)
        np.divide(1.0, t[1:], out=t[1:])  # t1, c2, c3, c4
        g = t[1] - t[0]
        g -= t[2]
        g -= t[3]
        sq = t * t
        dg = sq[0] + sq[1]
        np.subtract(sq[2], dg, out=dg)
        dg += sq[3]
        sq += 1.0
        sq *= t  # t (1 + t^2)
        half = sq[1] - sq[0]  # d2g / 2
        half -= sq[2]
        half -= sq[3]
        pos = g > 0.0
        b = np.where(pos, x, b)
        a = np.where(pos, a, x)
        np.divide(g, dg, out=g)  # the Newton step n
        np.divide(half, dg, out=half)
        half *= g
        fac = np.subtract(1.0, half, out=half)  # Halley's step is n / fac
        ok = dg > 0.0
        ok &= fac > 0.0
        np.divide(g, fac, out=g)
        newton = np.subtract(x, g, out=g)
        # a step onto a bracket end is kept (the root then sits within rounding of that end)
        ok &= newton >= a
        ok &= newton <= b
        mid = a + b
        mid *= 0.5
        x_new = np.where(ok, newton, mid)
        step = np.subtract(x_new, x, out=mid)
        np.abs(step, out=step)
        going = step >= tol
        out[active] = x_new
        it += 1
        left = np.count_nonzero(going)
        if left == 0:
            break
        if left < k:
            active, x_new, a, b, al, ss = (v[going] for v in (active, x_new, a, b, al, ss))
            if per_sample_phi:
                ph = ph[going]
        x = x_new
    return out


def _newton_tail(x: list, a: list, b: list, al: list, ph: list, ss: list, tol: float, steps: int) -> list[float]:
    """:func:`_bracketed_newton`'s iteration on Python floats (lists, updated in place) for the last few samples,
    each for at most ``steps`` steps and stopping on its own step; returns their final iterates. The samples still
    going share one ``np.tan`` call per step (NumPy's values; ``math.tan`` may differ in the last bit), the rest
    is the same IEEE arithmetic as the array loop's, so the iterates are the same."""
    inf, copysign = math.inf, math.copysign
    out, live = list(x), list(range(len(x)))
    while live and steps > 0:
        steps -= 1
        args: list[float] = []
        for m in live:
            u = al[m] + x[m]
            args += (u, u + ph[m], x[m], x[m] + ss[m])
        t, going = np.tan(np.array(args)).tolist(), []
        for j, m in enumerate(live):
            t1, t2, t3, t4 = t[4 * j:4 * j + 4]
            c2 = 1.0 / t2 if t2 != 0.0 else copysign(inf, t2)
            c3 = 1.0 / t3 if t3 != 0.0 else copysign(inf, t3)
            c4 = 1.0 / t4 if t4 != 0.0 else copysign(inf, t4)
            g, dg, xm = -t1 + c2 - c3 - c4, -t1 * t1 - c2 * c2 + c3 * c3 + c4 * c4, x[m]
            half = (c2 * c2 + 1.0) * c2 - (t1 * t1 + 1.0) * t1 - (c3 * c3 + 1.0) * c3 - (c4 * c4 + 1.0) * c4
            (b if g > 0.0 else a)[m] = xm
            newton = a[m] - 1.0  # the array loop's ok: dg > 0, fac > 0 and a <= newton <= b
            if dg > 0.0:
                n = g / dg
                fac = 1.0 - n * (half / dg)
                if fac > 0.0:
                    newton = xm - n / fac
            x_new = out[m] = newton if a[m] <= newton <= b[m] else 0.5 * (a[m] + b[m])
            if abs(x_new - xm) >= tol:
                x[m] = x_new
                going.append(m)
        live = going
    return out


def optimal_beta_scalar(alpha: float, rho: float, phi: float, delta: float,
                        options: ModelOptions = DEFAULT_OPTIONS, guess: float | None = None) -> float:
    """Scalar fast path of :func:`optimal_beta` (pure ``math``), optionally warm-started, else from
    :func:`cold_start`.

    The bracket checks and the loop of :func:`halley_step` on :func:`log_ngamma_derivatives`, written out with the
    same expressions in the same order (the env steps through here; a function call per step cost as much as the
    step's arithmetic), so the result is bit for bit the loop's (``tests/test_scalar_paths.py`` checks it).
    """
    s = rho + delta + phi
    lo = options.eps1
    hi = min(math.pi - s - options.eps2, 0.5 * math.pi - alpha)
    tan = math.tan
    if -tan(alpha + lo) + 1.0 / tan(alpha + lo + phi) - 1.0 / tan(lo) - 1.0 / tan(lo + s) >= 0.0:
        return lo  # g(lo) >= 0
    b_hi = -tan(alpha + hi) + 1.0 / tan(alpha + hi + phi)
    if b_hi - 1.0 / tan(hi) - 1.0 / tan(hi + s) <= 0.0:
        return hi  # g(hi) <= 0
    if guess is not None and lo < guess < hi:
        x = guess
    else:
        t_s = tan(s)
        x = cold_start(b_hi, 1.0 / t_s, math.sqrt, math.atan2) if t_s != 0.0 else math.nan
        if not lo < x < hi:
            x = 0.5 * (lo + hi)
    a, b = lo, hi
    for _ in range(60):
        t1 = tan(alpha + x)
        c2 = 1.0 / tan(alpha + x + phi)
        c3 = 1.0 / tan(x)
        c4 = 1.0 / tan(x + s)
        g = -t1 + c2 - c3 - c4
        dg = -t1 * t1 - c2 * c2 + c3 * c3 + c4 * c4
        if g > 0.0:
            b = x
        else:
            a = x
        xn = a - 1.0
        if dg > 0.0:
            n = g / dg
            half = (c2 * c2 + 1.0) * c2 - (t1 * t1 + 1.0) * t1 - (c3 * c3 + 1.0) * c3 - (c4 * c4 + 1.0) * c4
            fac = 1.0 - n * (half / dg)
            if fac > 0.0:
                xn = x - n / fac
        if not a <= xn <= b:
            xn = 0.5 * (a + b)
        if abs(xn - x) < 1e-11:
            return xn
        x = xn
    return x


def unrolled_beta(alpha, phi, s, lo, hi, steps: int, *, tan, clip, positive):
    """beta* by ``steps`` guarded Newton steps from the middle of the branch, for symbolic backends.

    Parameters
    ----------
    alpha, phi, s : expression
        Clamped slope, friction angle and ``s = rho + delta + phi`` [rad].
    lo, hi : expression
        Branch bounds (:func:`beta_bounds`).
    steps : int
        Number of unrolled Newton steps.
    tan : callable
        Tangent of the backend.
    clip : callable
        ``clip(value, lo, hi)``: (smooth) clamp into the branch after each step; a step that runs past
        a bound is returned there, as the bracketed NumPy solver does.
    positive : callable
        (Smooth) floor of the curvature ``dg`` that keeps each step a descent step.
    """
    beta = 0.5 * (lo + hi)
    for _ in range(steps):
        g, dg = log_ngamma_slope(beta, alpha, phi, s, tan=tan)
        beta = clip(beta - g / positive(dg), lo, hi)
    return beta


#: Failure-angle rules of :class:`~wheelloader.estimator.validity.ModelOptions` (the second:
#: :mod:`~wheelloader.estimator.failure_angle_weight`).
FAILURE_ANGLE_RULES = ("min_n_gamma", "min_weight_force")
