"""The cycle-to-cycle adaptation loop: dig, calibrate, predict, plan, dig again.

One loop runs ``cycles`` digging cycles in a :class:`~wheelloader.envs.BucketLoadingEnv`
(the plant: hidden soil, sensor noise, optional truths beyond the model) on a
pile that each cycle carves for the next. A :class:`Strategy` decides, between
cycles, which soil parameters to believe and which path to dig next:

* ``fixed``: the default Bezier path (moved to the current pile face) and
  nominal parameters, never recalibrated — the baseline;
* ``ours``: calibrate with the default method (warm-started), plan with them;
* ``paper``: calibrate with the paper's multi-stage method, plan with them;
* ``oracle``: plan with the plant's true soil (an upper bound on what
  calibration can give).

Nothing hides a failure: a calibration that raises or reports
``success=False`` keeps the previous parameters, a plan that fails falls back
to the Bezier path moved to the current face, and both are reported in the
cycle's record.
"""

from __future__ import annotations

import functools
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from wheelloader.estimator import (
    FLAG_OUT_OF_SOIL,
    BucketPath,
    CycleLog,
    Pile,
    SoilParams,
    WheelloaderError,
    calibrate,
    predict,
    preset,
)
from wheelloader.planner import (
    LOOP_EXIT_MIN_FILL,
    PlannerOptions,
    PlanOutcome,
    bezier_on_face,
    cautious_options,
    model_bezier_on_face,
    optimizer_for,
    plan_next_cycle,
)

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


class Strategy:
    """Decides which parameters to believe and which path to dig next.

    Subclasses override :meth:`update` (after a cycle) and :meth:`plan`.
    """

    name = "strategy"

    def __init__(self, nominal: SoilParams, rate: float = 60.0) -> None:
        self.params = nominal
        self.rate = rate
        self.last_good_path: BucketPath | None = None

    def update(self, log: CycleLog, true_soil: SoilParams) -> tuple[float, bool, str]:
        """Learn from the cycle just dug; return ``(seconds, ok, message)``."""
        return 0.0, True, "no calibration"

    def plan(self, pile: Pile) -> PlanOutcome:
        """Choose the next path on ``pile``."""
        start = time.perf_counter()
        return PlanOutcome(bezier_on_face(pile, self.rate), True, "fixed Bezier path", time.perf_counter() - start)


class FixedBezier(Strategy):
    """Baseline (a): the default Bezier path and nominal parameters, never recalibrated."""

    name = "fixed"


class Calibrating(Strategy):
    """Calibrate after every cycle (warm start), then plan with ``planner`` (or dig the Bezier path)."""

    def __init__(self, nominal: SoilParams, method: str = "default", planner: Any = None, rate: float = 60.0,
                 name: str | None = None) -> None:
        super().__init__(nominal, rate)
        self.method = method
        self.planner = planner
        self.previous = None
        self.name = name or ("ours" if method == "default" else "paper")

    def update(self, log: CycleLog, true_soil: SoilParams) -> tuple[float, bool, str]:
        start = time.perf_counter()
        try:
            result = calibrate(log, method=self.method, initial=self.previous)
        except WheelloaderError as exc:
            return time.perf_counter() - start, False, f"calibration failed, previous parameters kept: {exc}"
        seconds = time.perf_counter() - start
        if not result.success:
            return seconds, False, f"calibration did not converge, previous parameters kept: {result.message}"
        self.previous = result
        self.params = result.params
        return seconds, True, f"F_R fit {result.quality.percent_r:.1f} %"

    def plan(self, pile: Pile) -> PlanOutcome:
        if self.planner is None:
            return super().plan(pile)
        start = time.perf_counter()
        try:
            outcome = self.planner(self.params, pile)
        except WheelloaderError as exc:
            outcome = PlanOutcome(None, False, f"planner raised: {exc}", 0.0)
        outcome.seconds = time.perf_counter() - start
        if outcome.path is None or not outcome.success:
            # the last good path was planned for another (uncarved) surface: the safe fallback is the
            # baseline Bezier path moved to the current face
            fallback = model_bezier_on_face(self.params, pile, self.rate)
            return PlanOutcome(fallback, False, f"{outcome.message}; fell back to the {fallback.name} path",
                               time.perf_counter() - start)
        self.last_good_path = outcome.path
        return outcome


class Oracle(Calibrating):
    """Baseline (c): plan with the plant's true soil."""

    def __init__(self, planner: Any = None, rate: float = 60.0) -> None:
        super().__init__(preset(NOMINAL_SOIL), "oracle", planner, rate, name="oracle")

    def update(self, log: CycleLog, true_soil: SoilParams) -> tuple[float, bool, str]:
        self.params = true_soil
        return 0.0, True, "true soil"


class PolicyStrategy(Strategy):
    """Baseline (e): a trained policy (e.g. stable-baselines3 PPO) digs every cycle; no calibration."""

    name = "rl"

    def __init__(self, policy: Any, nominal: SoilParams | None = None) -> None:
        super().__init__(nominal or preset(NOMINAL_SOIL))
        self.policy = policy

    def plan(self, pile: Pile) -> PlanOutcome:
        def act(obs: np.ndarray) -> np.ndarray:
            action, _ = self.policy.predict(obs, deterministic=True)
            return action

        return PlanOutcome(None, True, "policy", 0.0, controller=act)


def run_loop(env: Any, strategy: Strategy, cycles: int = 5, seed: int = 0,
             progress: Callable[[str], None] | None = None) -> tuple[list[CycleRecord], list[CycleLog]]:
    """Run ``cycles`` digging cycles of ``strategy`` on ``env`` (a ``BucketLoadingEnv``).

    Between cycles the strategy calibrates on the cycle just dug and plans
    the next one on the carved pile. The first cycle starts from the env's
    pile with the strategy's prior parameters.

    Returns
    -------
    records, logs
        One :class:`CycleRecord` and one :class:`~wheelloader.estimator.CycleLog` per cycle.
    """
    from wheelloader.envs.scripted import PathTracker

    if not isinstance(cycles, int) or cycles < 1:
        raise WheelloaderError(f"cycles must be a positive integer, got {cycles!r}")
    base = env.unwrapped
    records: list[CycleRecord] = []
    logs: list[CycleLog] = []
    calib = (0.0, True, "prior parameters")
    obs, info = env.reset(seed=seed)
    for k in range(1, cycles + 1):
        if k > 1:
            obs, info = env.reset(options={"keep_pile": True, "soil": "keep"})
        pile = base.start_pile
        plan = strategy.plan(pile)
        controller = plan.controller or PathTracker(plan.path, base.cfg.loader, base.cfg.control_rate)
        params_used = strategy.params
        terminated = truncated = False
        violations = 0
        while not (terminated or truncated):
            obs, _, terminated, truncated, info = env.step(controller(obs))
            if int(info["flags"]) & ~FLAG_OUT_OF_SOIL and info["depth"] > 0.0:
                violations += 1
        log = base.last_cycle_log() if terminated else _finish(env)
        logs.append(log)
        quality = predict(params_used, log).quality
        fill = float(info["fill_volume"])
        energy = float(info["energy_soil"] + info["energy_payload"])
        records.append(CycleRecord(
            cycle=k, strategy=strategy.name, path=plan.path.name if plan.path is not None else "controller",
            calibration_s=calib[0], planning_s=plan.seconds,
            prediction_rmse_N=quality.rmse_r if quality else math.nan,
            prediction_rmse_percent=quality.percent_r if quality else math.nan,
            fill_m3=fill, fill_fraction=float(info["fill_fraction"]), energy_J=energy,
            energy_per_m3=energy / fill if fill > 0 else math.inf, stalled=bool(info["stalled"]),
            validity_violations=violations, end=log.metadata.get("end", ""),
            calibration_ok=calib[1], calibration_message=calib[2], plan_ok=plan.success,
            plan_message=plan.message, params=params_used.to_dict()))
        if progress is not None:
            progress(_progress_line(records[-1]))
        if k < cycles:
            calib = strategy.update(log, base.soil)
    return records, logs


def _finish(env: Any) -> CycleLog:
    """Close a cycle that hit the time limit and return its log."""
    env.reset(options={"keep_pile": True, "soil": "keep"})
    return env.unwrapped.cycle_logs()[-1]


def _progress_line(r: CycleRecord) -> str:
    flag = "" if r.calibration_ok and r.plan_ok else "  [!] " + "; ".join(
        m for ok, m in ((r.calibration_ok, r.calibration_message), (r.plan_ok, r.plan_message)) if not ok)
    return (f"  {r.strategy:>7} cycle {r.cycle}: fill {r.fill_fraction:5.0%}, energy {r.energy_J / 1e3:6.2f} kJ, "
            f"prediction F_R RMSE {r.prediction_rmse_percent:5.1f} %{flag}")


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


#: Work budget of the plan between cycles: IPOPT iterations per solve. A plan stopped at this limit is used
#: only when it passes the NumPy check (feasible, not proven optimal); otherwise it is re-planned with wider
#: margins while at most the budget is spent, and then the loop falls back to
#: :func:`~wheelloader.planner.model_bezier_on_face`. An iteration count, not a wall time, so that the same
#: seed gives the same cycles on a quiet and on a busy machine.
BETWEEN_CYCLES_MAX_ITER = 130


def default_planner(mpc: bool = False) -> Callable[[SoilParams, Pile], PlanOutcome]:
    """The planner used between cycles.

    A full-cycle CasADi plan within :data:`BETWEEN_CYCLES_MAX_ITER` IPOPT
    iterations, checked with the NumPy model, tracked in the env; with
    ``mpc`` an MPC controller re-plans the rest of the cycle every 0.1 s
    (slower, see the planner benchmark).
    """
    options = PlannerOptions(max_iter=BETWEEN_CYCLES_MAX_ITER)
    # build the NLPs once (the plan and its two wider-margin re-plans), before the loop's timings start
    for level in (0, 1, 2):
        optimizer_for(options=cautious_options(options, level))
    return functools.partial(plan_next_cycle, mpc=mpc, options=options,
                             replan_within_iterations=BETWEEN_CYCLES_MAX_ITER, exit_min_fill=LOOP_EXIT_MIN_FILL)
