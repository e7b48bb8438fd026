"""Re-simulate a planned path with the NumPy force model and check every constraint.

The planner optimises a smooth CasADi copy of the model on a coarse time
grid; :func:`verify_plan` samples the plan at the control rate and checks it
against the estimator's own :func:`~wheelloader.estimator.soil_forces` on the
true (unsmoothed) pile, so a plan that passes is feasible for the model the
env simulates, not only for the planner's approximation of it.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from wheelloader.envs.bookkeeping import cycle_done, cycle_progress, outside_validity, step_work
from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    GRAVITY,
    Bucket,
    BucketPath,
    Loader,
    ModelOptions,
    PayloadOptions,
    Pile,
    PlanningError,
    SoilParams,
    as_soil,
    contact_state,
    soil_forces,
)
from wheelloader.estimator.learned import default_learned_model, learned_forces
from wheelloader.estimator.payload import with_payload

from .options import PlannerOptions
from .plan import Plan

#: How far below its clearance the NumPy check lets the heel go [m] (the NLP sees a smoothed surface).
HEEL_TOLERANCE = 0.02
#: Height [m] and downward speed [m/s] within which the check lets the tip come down from above the opt-in
#: ``descend_clearance``: the NLP's switch is smooth over about 2 cm, and the surface under a descending interval
#: can drop.
DESCEND_TOLERANCE = 0.04
DESCEND_SPEED_TOLERANCE = 0.05


@dataclass(frozen=True)
class PlanCheck:
    """Outcome of :func:`verify_plan` (forces in N, speeds in m/s, angles in rad).

    ``ok`` is true when every check passed; ``failures`` names those that did not. ``fill`` is the force
    model's fill at the end [m^3] (the payload's kept soil under ``"fee-payload"``), ``carved`` the carved
    volume (the two are equal under ``"fee"``).
    """

    ok: bool
    failures: tuple[str, ...]
    max_tangential: float
    max_normal: float
    max_speed: float
    max_tilt_rate: float
    max_acceleration: float
    validity_violations: int
    min_rho_in_soil: float
    fill: float
    spilled: float
    energy: float
    end_clearance: float
    backward_steps: int
    details: dict[str, Any] = field(default_factory=dict)
    carved: float = math.nan

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable mapping."""
        out = asdict(self)
        out["failures"] = list(self.failures)
        return out


def path_energy(path: BucketPath, soil: SoilParams, pile: Pile, bucket: Bucket,
                initial_fill: float = 0.0, model_options: ModelOptions = DEFAULT_OPTIONS,
                payload: PayloadOptions | None = None, learned: bool = False) -> dict[str, np.ndarray | float]:
    """Forces, fill and the env's energy bookkeeping along ``path`` with the NumPy model (``initial_fill``
    [m^3] already in the bucket at its start; ``model_options``: the force model's, e.g. the opt-in
    failure-angle rule of the planner's :attr:`PlannerOptions.model_options`; ``payload``: under
    ``"fee-payload"`` (:attr:`PlannerOptions.force_payload`) the payload whose kept soil of the carved volume is
    the fill and the carried load, weight only); ``learned``: ``"fee-learned"``, the learned correction added
    (:func:`~wheelloader.estimator.learned.learned_forces`, at the path's finite-difference speed).

    Energy per step: the env's :func:`~wheelloader.envs.bookkeeping.step_work` (work on the soil plus
    lifting work on the payload), with the forces and blade angle at the step's end.

    Returns a dict: ``state``, ``forces``, ``energy`` [J], ``fill`` (the model's fill at the end: the kept soil
    under a payload), ``fill_history`` (per sample), ``carved`` and ``spilled`` [m^3].
    """
    state = contact_state(path.x, path.z, path.blade_angle, pile, bucket, initial_fill=initial_fill)
    carved = float(state.fill_volume[-1])
    if payload is not None:
        state = with_payload(state, bucket.capacity, payload, blade_angle=path.blade_angle)
    forces = soil_forces(soil, state, bucket, model_options)
    if learned:
        lf = learned_forces(default_learned_model(), state, path, bucket, soil)
        f_t, f_n = forces.tangential + lf.tangential, forces.normal + lf.normal
        forces = replace(forces, tangential=f_t, normal=f_n, resultant=np.hypot(f_t, f_n))
    fill = state.fill_volume if payload is None else state.carried_volume
    e_soil, e_payload = step_work(forces.tangential[1:], forces.normal[1:], np.diff(path.x), np.diff(path.z),
                                  path.blade_angle[1:], soil.gamma * GRAVITY * fill[1:])
    energy = float(np.sum(e_soil) + np.sum(e_payload))
    return {"state": state, "forces": forces, "energy": energy, "fill": float(fill[-1]), "fill_history": fill,
            "carved": carved, "spilled": float(state.carve.spilled) if state.carve is not None else 0.0}


def verify_plan(plan: Plan | BucketPath, soil: SoilParams | str | dict, pile: Pile, bucket: Bucket | None = None,
                loader: Loader | None = None, options: PlannerOptions | None = None, rate: float = 60.0,
                tolerance: float = 0.02, exit_clearance: float = 0.02, exit_min_fill: float = 0.0,
                tracking_margin: float = 0.01) -> PlanCheck:
    """Check a plan against the NumPy model and the machine's limits.

    Checks: forces within the loader's limits (the plan's ``force_margin`` is
    the planner's own safety factor; the check uses the hard limits), speed
    and tilt-rate limits, acceleration between the plan's intervals, every
    in-soil sample inside the model's validity domain (no flag but "tip out of
    soil"), the bucket not over its capacity (nothing spilled), forward motion
    only, the end pose at least ``end_clearance / 2`` above the surface, and
    no early end of the cycle (see ``exit_clearance``).
    ``tolerance`` is the relative slack on the rate limits (numerical rounding
    of the solver).

    Parameters
    ----------
    plan : Plan or BucketPath
        What to check (a :class:`Plan` is sampled at ``rate``).
    soil : SoilParams, preset name or dict
        Soil the forces are computed with.
    pile : Pile
        Surface at the start of the cycle.
    bucket, loader, options : optional
        Machine and planner settings (defaults as the planner's).
    rate : float
        Sampling rate of the re-simulation [Hz].
    tolerance : float
        Relative slack on speed and acceleration limits.
    exit_clearance, exit_min_fill : float
        The env's end-of-cycle rule (``BucketLoadingEnv``'s options of the
        same names): a tip that has been in soil with at least
        ``exit_min_fill`` of the capacity loaded and then rises more than
        ``exit_clearance`` [m] above the surface ends the cycle there, so a
        path that does so and later digs again fails the check.
    tracking_margin : float
        How much closer than ``exit_clearance`` to the surface the path must
        stay for that check [m] (default 0.01 m: tracking error and the
        env's start noise).

    Returns
    -------
    PlanCheck
    """
    soil = as_soil(soil)
    bucket = bucket or Bucket()
    loader = loader or Loader()
    options = options or PlannerOptions()
    path, accel, initial_fill = _sampled(plan, rate, bucket)
    sim = path_energy(path, soil, pile, bucket, initial_fill, options.model_options, options.force_payload,
                      options.force_model == "fee-learned")
    forces, state = sim["forces"], sim["state"]
    dt = np.diff(path.t)
    vx, vz, om = np.diff(path.x) / dt, np.diff(path.z) / dt, np.diff(path.blade_angle) / dt
    in_soil = state.depth > 0.0
    bad = outside_validity(state.depth, forces.flags)
    end_clear = float(path.z[-1] - pile.surface_height(float(path.x[-1])))
    early_exit = premature_exit(path, pile, state.depth, sim["fill_history"] / bucket.capacity,
                                exit_clearance - tracking_margin, exit_min_fill)
    slack = 1.0 + tolerance
    off_blade = _off_blade_steps(path, state.depth, vx, vz, options)
    heel_buried = _heel_buried_steps(path, pile, bucket, options)
    from_above = _descend_steps(path, pile, vz, options)
    checks = {
        "tangential force above the loader's push limit": float(forces.tangential.max()) > loader.max_push_force,
        "normal force above the loader's lift limit": float(forces.normal.max()) > loader.max_lift_force,
        "speed above the loader's limit": float(np.max(np.abs(np.concatenate([vx, vz])))) > loader.max_speed * slack,
        "tilt rate above the loader's limit": float(np.max(np.abs(om))) > loader.max_tilt_rate * slack,
        "acceleration above the loader's limit": accel > loader.max_acceleration * slack,
        "tip in soil outside the model's validity domain": bool(np.any(bad)),
        "bucket over capacity (soil spilled)": sim["spilled"] > 1e-3 * bucket.capacity,
        "tip moves backwards": bool(np.any(vx < -1e-6)),
        "path does not end out of the pile": end_clear < 0.5 * options.end_clearance,
        "tip leaves the soil before the end (the env would end the cycle there)": early_exit is not None,
        "bucket moves off its blade in soil (outside the cutting cone)": off_blade > 0,
        "bucket's heel in the soil (below the heel clearance)": heel_buried > 0,
        "tip comes down onto the pile from above (above the descend clearance)": from_above > 0,
        "bucket not curled at the end (below the end blade angle)": (
            options.end_blade_angle is not None and float(path.blade_angle[-1]) < options.end_blade_angle - 0.02),
    }
    failures = tuple(name for name, failed in checks.items() if failed)
    rho_in = state.rho[in_soil]
    return PlanCheck(
        ok=not failures, failures=failures,
        max_tangential=float(forces.tangential.max()), max_normal=float(forces.normal.max()),
        max_speed=float(np.max(np.abs(np.concatenate([vx, vz])))), max_tilt_rate=float(np.max(np.abs(om))),
        max_acceleration=accel, validity_violations=int(np.count_nonzero(bad)),
        min_rho_in_soil=float(rho_in.min()) if rho_in.size else math.nan,
        fill=sim["fill"], spilled=sim["spilled"], energy=sim["energy"], end_clearance=end_clear,
        backward_steps=int(np.count_nonzero(vx < -1e-6)), carved=sim["carved"],
        details={"flags": forces.flag_summary(), "samples": len(path), "early_exit_s": early_exit,
                 "off_blade_steps": off_blade, "heel_buried_steps": heel_buried,
                 "descend_steps": from_above},
    )



def _sampled(plan: Plan | BucketPath, rate: float, bucket: Bucket) -> tuple[BucketPath, float, float]:
    """The path to re-simulate, its largest acceleration [m/s^2] and the fill at its start [m^3]."""
    initial_fill = 0.0
    if isinstance(plan, Plan):
        path = plan.path(rate)
        accel = _interval_acceleration(plan)
        start = plan.raw.get("start")
        initial_fill = min(start.fill, bucket.capacity) if start is not None else 0.0
    elif isinstance(plan, BucketPath):
        path = plan
        vx, vz, _ = path.velocity()
        accel = float(np.max(np.abs(np.diff(np.column_stack([vx, vz]), axis=0)) / np.diff(path.t)[:, None]))
    else:
        raise PlanningError(f"plan must be a Plan or a BucketPath, got {type(plan).__name__}")
    return path, accel, initial_fill


def _off_blade_steps(path: BucketPath, depth: np.ndarray, vx: np.ndarray, vz: np.ndarray,
                     options: PlannerOptions) -> int:
    """Steps in soil moving outside the opt-in cutting cone (``PlannerOptions.cut_angle``); 0 without it."""
    if options.cut_angle is None:
        return 0
    th = path.blade_angle[1:]
    along = vx * np.cos(th) + vz * np.sin(th)
    deep = (depth[1:] > options.cut_depth) & (np.hypot(vx, vz) > 1e-3)
    return int(np.count_nonzero(deep & (along < math.cos(options.cut_angle + 0.05) * np.hypot(vx, vz))))


def _heel_buried_steps(path: BucketPath, pile: Pile, bucket: Bucket, options: PlannerOptions) -> int:
    """Samples with the heel below the opt-in heel clearance (``PlannerOptions.heel_clearance``); 0 without it."""
    if options.heel_clearance is None:
        return 0
    heel_x = path.x - bucket.floor_length * np.cos(path.blade_angle)
    heel_z = path.z - bucket.floor_length * np.sin(path.blade_angle)
    return int(np.count_nonzero(heel_z - pile.surface_height(heel_x) < options.heel_clearance - HEEL_TOLERANCE))

def premature_exit(path: BucketPath, pile: Pile, depth: np.ndarray, fill_fraction: np.ndarray,
                   exit_clearance: float = 0.02, exit_min_fill: float = 0.0) -> float | None:
    """Time at which the env would end the cycle before the path is done digging, or None [s].

    The env ends a cycle by its rule (:func:`cycle_end_index`). That is
    premature when the path is in soil again at a later sample (it hopped out
    and meant to dig on).
    """
    in_soil = np.asarray(depth) > 0.0
    clearance = path.z - np.asarray(pile.surface_height(path.x))
    end = cycle_end_index(in_soil, clearance, fill_fraction, exit_clearance, exit_min_fill, z=path.z,
                          crest=float(np.max(pile.heights)))
    if end is None or not np.any(in_soil[end + 1:]):
        return None
    return float(path.t[end])


def cycle_end_index(in_soil: np.ndarray, clearance: np.ndarray, fill_fraction: np.ndarray,
                    exit_clearance: float = 0.02, exit_min_fill: float = 0.0, *, z: np.ndarray | None = None,
                    crest: float | None = None) -> int | None:
    """Sample at which ``BucketLoadingEnv`` ends a cycle along a path, or None when it does not.

    The env's rule (:func:`~wheelloader.envs.bookkeeping.cycle_done`): the first
    sample where the tip has been in soil with at least ``exit_min_fill`` of the
    capacity loaded (``fill_fraction``) and is more than ``exit_clearance`` [m]
    above the start surface (``clearance``); with the tip heights ``z`` [m] and
    the pile's ``crest`` [m] given, also where it has touched the soil with less
    loaded and is more than ``exit_clearance`` above the crest.
    """
    in_soil = np.asarray(in_soil, dtype=bool)
    touched, loads = cycle_progress(False, False, in_soil, np.asarray(fill_fraction), exit_min_fill)
    done = cycle_done(np.logical_or.accumulate(touched), np.logical_or.accumulate(loads),
                      0.0 if z is None else np.asarray(z), np.asarray(clearance),
                      np.inf if crest is None else crest, exit_clearance)
    ends = np.nonzero(done)[0]
    return int(ends[0]) if ends.size else None


def _interval_acceleration(plan: Plan) -> float:
    """Largest change of the interval velocities per interval length [m/s^2] (from rest at the start)."""
    h = float(plan.t[1] - plan.t[0])
    start = plan.raw.get("start")
    v0 = np.array([[start.vx, start.vz]]) if start is not None else np.zeros((1, 2))
    v = np.vstack([v0, np.column_stack([plan.vx, plan.vz])])
    return float(np.max(np.abs(np.diff(v, axis=0))) / h)


def _descend_steps(path: BucketPath, pile: Pile, vz: np.ndarray, options: PlannerOptions) -> int:
    """Steps that move the tip down while it starts them more than the opt-in ``descend_clearance`` (plus
    :data:`DESCEND_TOLERANCE`) above the surface (``PlannerOptions.descend_clearance``); 0 without it."""
    if options.descend_clearance is None:
        return 0
    above = (path.z - pile.surface_height(path.x))[:-1] > options.descend_clearance + DESCEND_TOLERANCE
    return int(np.count_nonzero(above & (vz < -DESCEND_SPEED_TOLERANCE)))
