"""The cycle-to-cycle adaptation loop: dig, calibrate, predict, plan, dig again.

One loop runs ``cycles`` digging cycles in a :class:`~wheelloader.envs.BucketLoadingEnv` (the plant: hidden soil,
sensor noise, optional truths beyond the model) on a pile that each cycle carves for the next. A :class:`Strategy`
decides, between cycles, which soil parameters to believe and which path to dig next:

* ``fixed``: the default Bezier path (moved to the current pile face) and nominal parameters, never
  recalibrated — the baseline;
* ``ours``: calibrate with the default method on the last ``window`` cycles together
  (:data:`DEFAULT_WINDOW`; warm-started from the previous fit), plan with them;
* ``paper``: calibrate with the paper's multi-stage method, plan with them;
* ``oracle``: plan with the plant's true soil (an upper bound on what calibration can give).

Nothing hides a failure: a calibration that raises or reports ``success=False`` keeps the previous parameters,
and so does (with ``keep_untrustworthy=False``; not the default, see :class:`Calibrating`) a fit whose verdict
says the data could not determine the soil while an earlier, trustworthy fit exists; a plan that fails falls
back to the Bezier path moved to the current face, and both are reported in the cycle's record.
"""

from __future__ import annotations

import functools
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field
from typing import Any

from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    BucketPath,
    CalibrationOptions,
    CycleLog,
    ModelOptions,
    PayloadOptions,
    Pile,
    SoilParams,
    WheelloaderError,
    calibrate,
    preset,
)
from wheelloader.estimator.force_models import DEFAULT_FORCE_MODEL, check_force_model, model_options_for
from wheelloader.loop_planner import (  # noqa: F401 (re-exported: the loop's planner lived here)
    BETWEEN_CYCLES_MAX_ITER,
    BETWEEN_CYCLES_REPLAN_ITER,
    LOOP_PLANNER_MIDPOINTS,
    default_planner,
)
from wheelloader.loop_prior import DEFAULT_PRIOR, PRIOR_NAMES, LoopPrior, loop_prior  # noqa: F401 (re-exported)
from wheelloader.planner import (
    LOOP_EXIT_MIN_FILL,
    PlanOutcome,
    bezier_on_face,
    model_bezier_on_face,
)

#: Cycles the ``ours`` strategy calibrates on together (the last ``DEFAULT_WINDOW`` cycles), chosen by measurement
#: on ``benchmarks/adaptation.py`` (18 loops of 5 cycles, drifting soil, truths beyond the model): next-cycle F_R
#: error 26.9 % with 1 cycle, 28.3 % with 2, 27.2 % with 3, 27.4 % with 5 (every converged fit adopted); older
#: cycles of a drifting soil do not help there, so the default is the last cycle alone.
DEFAULT_WINDOW = 1
#: Nominal (uncalibrated) parameters of the baselines: the "sand" preset, a middle-of-the-road soil.
NOMINAL_SOIL = "sand"
#: Keyword arguments of the loop's env besides soil, pile and truth: slump the pile between cycles, the
#: loop's end-of-cycle rule.
LOOP_ENV_KWARGS = {"relax": True, "exit_min_fill": LOOP_EXIT_MIN_FILL}
@dataclass
class CycleRecord:
    """Metrics of one digging cycle of one strategy (one row of the demo table)."""

    cycle: int
    strategy: str
    path: str
    calibration_s: float
    planning_s: float
    prediction_rmse_N: float
    prediction_rmse_percent: float
    fill_m3: float
    fill_fraction: float
    energy_J: float
    energy_per_m3: float
    stalled: bool
    validity_violations: int
    end: str
    calibration_ok: bool = True
    calibration_message: str = ""
    plan_ok: bool = True
    plan_message: str = ""
    params: dict[str, float] = field(default_factory=dict)

    @property
    def between_cycles_s(self) -> float:
        """Calibration + planning time before this cycle [s]."""
        return self.calibration_s + self.planning_s

    def to_dict(self) -> dict[str, Any]:
        out = asdict(self)
        out["between_cycles_s"] = self.between_cycles_s
        return out


@dataclass(frozen=True)
class CalibrationStep:
    """What a strategy did with the cycle just dug (:meth:`Strategy.update`): one row's calibration columns."""

    seconds: float
    """Time the calibration took [s]."""
    ok: bool
    """The strategy now believes parameters learnt from the cycle (False: it kept the previous ones)."""
    message: str
    """What happened, in words (the table's note when not ``ok``)."""

    @classmethod
    def of(cls, value: CalibrationStep | tuple[float, bool, str]) -> CalibrationStep:
        """``value`` as a step; the ``(seconds, ok, message)`` tuple that ``update`` returned before 0.2 is still
        taken, with a DeprecationWarning."""
        if isinstance(value, CalibrationStep):
            return value
        warnings.warn("Strategy.update returning (seconds, ok, message) is deprecated and will be refused in the "
                      "next release; return a wheelloader.adaptation.CalibrationStep", DeprecationWarning,
                      stacklevel=3)
        seconds, ok, message = value
        return cls(float(seconds), bool(ok), str(message))


class Strategy:
    """Decides which parameters to believe and which path to dig next.

    Subclasses override :meth:`update` (after a cycle) and :meth:`plan`.
    """

    name = "strategy"
    #: Force-model options, bucket-load source, force model and payload the strategy predicts (and calibrates and
    #: plans) with: the paper's model by default.
    model_options, fill, force_model, payload = DEFAULT_OPTIONS, "log", DEFAULT_FORCE_MODEL, None

    def __init__(self, nominal: SoilParams, rate: float = 60.0) -> None:
        self.params = nominal
        self.rate = rate
        self.last_good_path: BucketPath | None = None

    def update(self, log: CycleLog, true_soil: SoilParams) -> CalibrationStep:
        """Learn from the cycle just dug (``true_soil``: the plant's truth, which only an oracle reads)."""
        return CalibrationStep(0.0, True, "no calibration")

    def plan(self, pile: Pile) -> PlanOutcome:
        """Choose the next path on ``pile``."""
        start = time.perf_counter()
        return PlanOutcome(bezier_on_face(pile, self.rate), True, "fixed Bezier path", time.perf_counter() - start)


class FixedBezier(Strategy):
    """Baseline (a): the default Bezier path and nominal parameters, never recalibrated."""

    name = "fixed"


class Calibrating(Strategy):
    """Calibrate after every cycle (warm start), then plan with ``planner`` (or dig the Bezier path).

    Parameters
    ----------
    nominal : SoilParams
        Parameters believed before the first calibration.
    method : str
        Calibration method (``"default"``: varpro; the paper's methods take one cycle only).
    planner : callable, optional
        ``planner(params, pile) -> PlanOutcome``; None digs the Bezier path.
    rate : float
        Control rate [Hz] of the Bezier fallback.
    name : str, optional
        Strategy name in the tables.
    window : int, optional
        Calibrate on the last ``window`` cycles together (each on its own carved pile). Default
        :data:`DEFAULT_WINDOW` for the varpro method, 1 for the paper's methods.
    forgetting : float, optional
        Forgetting factor of the window's cycles (the newest weighs 1, the one before ``forgetting``, ...).
    keep_untrustworthy : bool
        Adopt a fit whose verdict is "not trustworthy" (:attr:`Calibration.trustworthy`) even when an
        earlier trustworthy fit exists (default True). False keeps the earlier fit and says so; measured
        on ``benchmarks/adaptation.py`` it raised the next-cycle error with a window of 1 cycle (27.6 %
        instead of 26.9 %) and lowered it with 3 (27.0 % instead of 27.2 %), so it is not the default.
    options : ModelOptions, optional
        Force-model options of the calibration and of the strategy's predictions (opt-in terms; the
        planner plans with the paper's model whatever they are).
    fill : str
        Bucket-load source of the calibration and predictions (``"log"`` or ``"model"``, see
        :func:`~wheelloader.estimator.calibrate`).
    force_model, payload : str, PayloadOptions
        The model calibrated (:data:`~wheelloader.estimator.FORCE_MODELS`); predictions and plans use the
        calibration's (the planner gets ``force_model=``, ``payload=`` when it is not ``"fee"``).
    prior : str or LoopPrior
        The calibration's prior (a name of :data:`~wheelloader.loop_prior.LOOP_PRIORS` or a
        :class:`LoopPrior`): ``"nominal"`` holds gamma, K and n softly at ``prior_soil`` and fits cohesion,
        adhesion, phi and delta; ``"held"`` holds all seven softly (:data:`~wheelloader.loop_prior.HELD_PRIOR`);
        ``"none"`` fits all freely (default :data:`DEFAULT_PRIOR`).
    prior_soil : SoilParams, optional
        The soil the prior is centred on (default ``nominal``): the soil preset the user names, of which the
        hidden soil is a perturbation.
    """

    def __init__(self, nominal: SoilParams, method: str = "default", planner: Any = None, rate: float = 60.0,
                 name: str | None = None, *, window: int | None = None, forgetting: float | None = None,
                 keep_untrustworthy: bool = True, options: ModelOptions | None = None,
                 fill: str = "log", force_model: str = DEFAULT_FORCE_MODEL,
                 payload: PayloadOptions | None = None, prior: str | LoopPrior = DEFAULT_PRIOR,
                 prior_soil: SoilParams | None = None) -> None:
        super().__init__(nominal, rate)
        self.prior = loop_prior(prior)
        self.prior_soil = nominal if prior_soil is None else prior_soil
        self.method = method
        self.planner = planner
        self.previous = None
        self.name = name or ("ours" if method == "default" else "paper")
        paper = method not in ("default", "varpro")
        if window is None:
            window = 1 if paper else DEFAULT_WINDOW
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise WheelloaderError(f"window must be a positive integer (cycles), got {window!r}")
        if paper and window > 1:
            raise WheelloaderError(f"the paper's method {method!r} calibrates on one cycle: window must be 1")
        self.window = window
        self.forgetting = forgetting
        self.keep_untrustworthy = keep_untrustworthy
        self.model_options = DEFAULT_OPTIONS if options is None else options
        self.fill = fill
        self.force_model, self.payload = force_model, check_force_model(force_model, payload, error=WheelloaderError)
        self.recent: list[CycleLog] = []

    def update(self, log: CycleLog, true_soil: SoilParams) -> CalibrationStep:
        self.recent = [*self.recent, log][-self.window:]
        start = time.perf_counter()
        cycles = self.recent if len(self.recent) > 1 else log
        try:
            result = calibrate(cycles, options=CalibrationOptions(
                method=self.method, initial=self.previous, forgetting=self.forgetting if len(self.recent) > 1 else None,
                model_options=self.model_options, fill=self.fill, force_model=self.force_model,
                payload=self.payload, held=self.prior.held(self.prior_soil, log.bucket.edge_thickness)))
        except WheelloaderError as exc:
            return CalibrationStep(time.perf_counter() - start, False,
                                   f"calibration failed, previous parameters kept: {exc}")
        seconds = time.perf_counter() - start
        if not result.success:
            return CalibrationStep(seconds, False,
                                   f"calibration did not converge, previous parameters kept: {result.message}")
        used = f"{len(self.recent)} cycles" if len(self.recent) > 1 else "1 cycle"
        if (not result.trustworthy and not self.keep_untrustworthy and self.previous is not None
                and self.previous.trustworthy):
            codes = ", ".join(w.code for w in result.warnings)
            return CalibrationStep(seconds, False, f"fit on {used} not trustworthy ({codes}), previous parameters kept")
        self.previous, self.params = result, result.params
        self.force_model, self.payload = result.force_model, result.payload  # the calibration's model
        return CalibrationStep(seconds, True, f"F_R fit {result.quality.percent_r:.1f} % on {used}")

    def plan(self, pile: Pile) -> PlanOutcome:
        if self.planner is None:
            return super().plan(pile)
        start = time.perf_counter()
        model = {} if self.payload is None else {"force_model": self.force_model, "payload": self.payload}
        try:
            outcome = self.planner(self.params, pile, **model)
        except WheelloaderError as exc:
            outcome = PlanOutcome(None, False, f"planner raised: {exc}", 0.0)
        outcome.seconds = time.perf_counter() - start
        if outcome.path is None or not outcome.success:
            # the last good path was planned for an uncarved surface: fall back to the Bezier path moved to the face
            kw = dict(model_options=model_options_for(self.force_model, self.model_options), payload=self.payload,
                      learned=self.force_model == "fee-learned")
            fallback = model_bezier_on_face(self.params, pile, self.rate, **kw)
            return PlanOutcome(fallback, False, f"{outcome.message}; fell back to the {fallback.name} path",
                               time.perf_counter() - start)
        self.last_good_path = outcome.path
        return outcome


class Oracle(Calibrating):
    """Baseline (c): plan with the plant's true soil."""

    def __init__(self, planner: Any = None, rate: float = 60.0) -> None:
        super().__init__(preset(NOMINAL_SOIL), "oracle", planner, rate, name="oracle")

    def update(self, log: CycleLog, true_soil: SoilParams) -> CalibrationStep:
        self.params = true_soil
        return CalibrationStep(0.0, True, "true soil")


def run_loop(env: Any, strategy: Strategy, cycles: int = 5, seed: int = 0,
             progress: Callable[[str], None] | None = None) -> tuple[list[CycleRecord], list[CycleLog]]:
    """Deprecated: run ``cycles`` cycles of ``strategy`` on ``env`` (a ``BucketLoadingEnv``).

    Use :func:`wheelloader.loop.run_loop` with the env behind the plant interface,
    ``run_loop(FEEEnvPlant(keep_env=True, **env_kwargs), strategy, pile, soil, cycles, seed=seed)``; this
    function is that loop on ``FEEEnvPlant(env=env)`` (the records are the same) and will be removed in the
    next release.
    """
    from wheelloader.loop import run_loop as one_loop
    from wheelloader.references.fee_env import FEEEnvPlant

    warnings.warn("wheelloader.adaptation.run_loop(env, ...) is deprecated and will be removed in the next release; "
                  "use wheelloader.loop.run_loop(FEEEnvPlant(keep_env=True, ...), strategy, pile, soil, cycles)",
                  DeprecationWarning, stacklevel=2)
    if not isinstance(cycles, int) or isinstance(cycles, bool) or cycles < 1:
        raise WheelloaderError(f"cycles must be a positive integer, got {cycles!r}")
    base = env.unwrapped
    return one_loop(FEEEnvPlant(env=env), strategy, base.cfg.pile, "the env's", cycles, seed=seed,
                    progress=progress)


#: Strategy names of :func:`make_strategy` (``rl`` needs a trained policy).
STRATEGY_NAMES: tuple[str, ...] = ("fixed", "ours", "oracle", "paper", "rl", "rl_path", "rl_closed")


def make_strategy(name: str, planner: Any = None, rl_policy: str | None = None,
                  ours_options: Mapping[str, Any] | None = None) -> Strategy:
    """A fresh strategy by name: ``fixed``, ``ours``, ``oracle``, ``paper``, or a trained policy's ``rl``,
    ``rl_path`` or ``rl_closed`` (a stable-baselines3 PPO ``.zip`` at ``rl_policy``,
    :func:`~wheelloader.policy_strategies.policy_strategy`); ``planner`` plans between cycles (None: Bezier paths);
    ``ours_options``: keyword arguments of ``ours``' :class:`Calibrating` (``window``, ``forgetting``,
    ``keep_untrustworthy``, ``prior``, ``prior_soil``, ...)."""
    if name == "fixed":
        return FixedBezier(preset(NOMINAL_SOIL))
    if name == "ours":
        return Calibrating(preset(NOMINAL_SOIL), "default", planner, **dict(ours_options or {}))
    if name == "oracle":
        return Oracle(planner)
    if name == "paper":
        return Calibrating(preset(NOMINAL_SOIL), "multi-stage", planner, name="paper")
    if name in ("rl", "rl_path", "rl_closed"):
        from wheelloader.policy_strategies import policy_strategy

        return policy_strategy(name, rl_policy)
    raise WheelloaderError(f"unknown strategy {name!r}; choose from {STRATEGY_NAMES}")


@functools.lru_cache(maxsize=4)
def _process_planner(mpc: bool, cut_angle: float | None = None, failure_angle: str = "min_n_gamma",
                     heel_clearance: float | None = None, end_blade_angle: float | None = None,
                     curl_out_intervals: int = 0, midpoints: bool | None = None
                     ) -> Callable[[SoilParams, Pile], PlanOutcome]:
    """:func:`default_planner`, built once per process (the NLPs are cached per process anyway)."""
    return default_planner(mpc=mpc, cut_angle=cut_angle, failure_angle=failure_angle, heel_clearance=heel_clearance,
                           end_blade_angle=end_blade_angle, curl_out_intervals=curl_out_intervals,
                           midpoints=midpoints)


def strategy_loop(*, soil: SoilParams, pile: Mapping[str, Any] | Pile, truth: Mapping[str, float],
                  strategy: str, cycles: int, seed: int, planner: str | None = "plan",
                  rl_policy: str | None = None, ours_options: Mapping[str, Any] | None = None,
                  cut_angle: float | None = None, heel_clearance: float | None = None,
                  end_blade_angle: float | None = None, curl_out_intervals: int = 0,
                  midpoints: bool | None = None) -> list[dict[str, Any]]:
    """One loop of the adaptation benchmark, self-contained so that it can run in another process (a
    :class:`wheelloader.sweep.Unit`): build the plant env and a fresh strategy, run
    :func:`wheelloader.loop.run_loop` on the env (:class:`~wheelloader.references.fee_env.FEEEnvPlant` with
    ``keep_env``).

    Parameters
    ----------
    soil, pile, truth
        The plant's hidden soil, its pile and its truths beyond the model (env keyword arguments, with
        :data:`LOOP_ENV_KWARGS`).
    strategy : str
        A name of :data:`STRATEGY_NAMES`.
    cycles, seed
        As :func:`run_loop`.
    planner : str or None
        ``"plan"`` (:func:`default_planner`), ``"mpc"`` (with the MPC) or None (Bezier paths only).
    rl_policy : str, optional
        The PPO ``.zip`` of strategy ``rl``.
    ours_options : mapping, optional
        Keyword arguments of strategy ``ours`` (:func:`make_strategy`).
    cut_angle, heel_clearance, end_blade_angle : float, optional
        The planner's opt-in cutting cone [rad], heel clearance [m] and end blade angle [rad]
        (:class:`~wheelloader.planner.PlannerOptions`).
    curl_out_intervals : int
        With ``end_blade_angle``: the plan's last intervals in which the bucket curls out of the pile
        (:class:`~wheelloader.planner.PlannerOptions`; default 0).
    midpoints : bool, optional
        The plan's forces and validity also at the intervals' midpoints (default: :func:`default_planner`'s).

    Returns
    -------
    list of dict
        :meth:`CycleRecord.to_dict` of every cycle.
    """
    from wheelloader.loop import run_loop
    from wheelloader.references.fee_env import FEEEnvPlant

    if planner not in ("plan", "mpc", None):
        raise WheelloaderError(f"planner must be 'plan', 'mpc' or None, got {planner!r}")
    # ours plans with the model it calibrates (its failure-angle rule); the others with the paper's
    model = (ours_options or {}).get("options") if strategy == "ours" else None
    rule = model.failure_angle if model is not None else "min_n_gamma"
    plan_fn = None if planner is None else _process_planner(planner == "mpc", cut_angle, rule, heel_clearance,
                                                            end_blade_angle, curl_out_intervals, midpoints)
    plant = FEEEnvPlant(keep_env=True, truth=dict(truth))
    try:
        records, _ = run_loop(plant, make_strategy(strategy, plan_fn, rl_policy, ours_options), pile, soil,
                              cycles=cycles, seed=seed)
    finally:
        plant.close()
    return [r.to_dict() for r in records]


def finish_cycle(env: Any) -> CycleLog:
    """Close a cycle that hit the time limit (the pile kept, as carved) and return its log."""
    env.reset(options={"keep_pile": True, "soil": "keep"})
    return env.unwrapped.cycle_logs()[-1]


def format_table(records: list[CycleRecord]) -> str:
    """The per-cycle table printed by the demo."""
    head = (f"{'cycle':>5} {'strategy':>8} {'calib s':>8} {'plan s':>7} {'pred F_R RMSE':>15} {'fill':>6} "
            f"{'energy kJ':>10} {'kJ/m^3':>8} {'stall':>5}  notes")
    lines = [head, "-" * len(head)]
    for r in records:
        notes = "; ".join(m for ok, m in ((r.calibration_ok, r.calibration_message), (r.plan_ok, r.plan_message))
                          if not ok)
        lines.append(f"{r.cycle:>5} {r.strategy:>8} {r.calibration_s:8.3f} {r.planning_s:7.3f} "
                     f"{r.prediction_rmse_N:7.0f} N {r.prediction_rmse_percent:4.1f}% {r.fill_fraction:6.0%} "
                     f"{r.energy_J / 1e3:10.2f} {r.energy_per_m3 / 1e3:8.1f} {'yes' if r.stalled else 'no':>5}  "
                     f"{notes}")
    return "\n".join(lines)


def hidden_default_soil() -> SoilParams:
    """The demo's hidden plant soil: gravel-like, but not the preset the user could guess."""
    g = preset("gravel")
    return g.replace(gamma=g.gamma * 1.06, phi=g.phi - 0.04, delta=g.delta + 0.03, k_c=g.k_c * 1.3)



#: The policy strategies live in their own module (this one's size); re-exported here, where they were, on first use
#: (the module imports this one: either may be imported first).
_POLICY_EXPORTS = ("PolicyClosedLoop", "PolicyPath", "PolicyStrategy", "policy_strategy")


def __getattr__(name: str) -> Any:
    if name in _POLICY_EXPORTS:
        from wheelloader import policy_strategies

        return getattr(policy_strategies, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
