"""Configuration shared by the single and the batched bucket-loading envs.

Both envs parse their keyword arguments here and draw their random numbers
through the helpers below in the same order, so that the same seed gives the
same trajectory in :class:`~wheelloader.envs.bucket_loading.BucketLoadingEnv`
and in :class:`~wheelloader.envs.vector.BucketLoadingVectorEnv`.
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any, NamedTuple

import numpy as np

from wheelloader.estimator import (
    DEFAULT_OPTIONS,
    Bucket,
    Loader,
    ModelOptions,
    ParameterError,
    PayloadOptions,
    Pile,
    SoilParams,
    as_soil,
)
from wheelloader.estimator.checks import check_finite, check_int, check_range
from wheelloader.estimator.force_models import DEFAULT_FORCE_MODEL, check_force_model, model_options_for
from wheelloader.estimator.payload import as_payload

from .piles import nominal_start_pose, parse_pile, pile_toe
from .soils import SoilRandomization, SoilSpec, drift_soil, parse_soil
from .truth import TruthOptions, as_truth, stone_decay

__all__ = ["BASE_OBS_NAMES", "BASE_OBS_UNITS", "DEFAULT_BLADE_ANGLE_LIMITS", "DEFAULT_LOOKAHEAD", "DEFAULT_START_NOISE",
           "NOISE_CHUNK", "REWARD_TERMS", "SETTING_NAMES", "EnvConfig", "RewardTerms", "RewardWeights", "SoilArgument",
           "SoilRandomization", "SoilSpec", "as_reward_weights", "check_relax", "choose_soil", "draw_noise_chunk",
           "draw_start_pose", "drift_soil", "next_pile", "nominal_start_pose", "parse_pile", "parse_soil", "pile_toe",
           "settings_parameters"]

#: Noise values are drawn in chunks of this many steps (one RNG call per chunk).
NOISE_CHUNK = 256
#: Episode limit per digging cycle of the registered envs [steps] (10 s at 60 Hz); the env applies it itself
#: when built from an env_config mapping (RLlib), where no ``gym.make`` adds a ``TimeLimit``.
STEPS_PER_CYCLE = 600

#: Names of the observation entries, in order (see the env docstring for units).
BASE_OBS_NAMES: tuple[str, ...] = (
    "x", "z", "blade_angle", "vx", "vz", "tilt_rate", "depth", "rho", "alpha", "fill_fraction",
    "force_tangential", "force_normal",
)
#: Units of the base observation entries.
BASE_OBS_UNITS: tuple[str, ...] = ("m", "m", "rad", "m/s", "m/s", "rad/s", "m", "rad", "rad", "-", "kN", "kN")

#: Default half-widths of the uniform start-pose noise (x [m], z [m], blade angle [rad]).
DEFAULT_START_NOISE: tuple[float, float, float] = (0.03, 0.01, math.radians(2.0))
#: Default blade-angle range [rad].
DEFAULT_BLADE_ANGLE_LIMITS: tuple[float, float] = (math.radians(-45.0), math.radians(75.0))
#: Default look-ahead distances of the surface observations [m].
DEFAULT_LOOKAHEAD: tuple[float, ...] = (0.1, 0.2, 0.3, 0.4, 0.5)


class RewardTerms(NamedTuple):
    """The five reward terms of a step (:func:`~wheelloader.envs.bookkeeping.reward_terms`); floats in the
    single env, arrays in the batched one. The reward is their sum in this order (:meth:`total`)."""

    fill: Any
    energy: Any
    validity: Any
    stall: Any
    force: Any

    def total(self) -> Any:
        """The reward: the terms summed in their order (the same floating-point result in every backend)."""
        return self.fill + self.energy + self.validity + self.stall + self.force


#: Keys of the reward terms in ``info`` (``"reward_" + RewardTerms field``); the reward is their sum in this order.
REWARD_TERMS: tuple[str, ...] = tuple(f"reward_{name}" for name in RewardTerms._fields)


@dataclass(frozen=True)
class RewardWeights:
    """Weights of the reward terms (all >= 0).

    Parameters
    ----------
    fill : float
        Reward per bucket capacity of fill gained [1/capacity]. Default 1.0: a
        full bucket is worth 1.
    energy : float
        Cost per joule of mechanical work on soil and payload [1/J]. Default
        1e-5 (10 kJ of work cost as much as a tenth of a bucket).
    validity : float
        Cost per step with the tip in soil outside the force model's validity
        domain (clamped rho or alpha, tension). Default 0.01.
    stall : float
        Cost per stalled step. Default 1.0.
    force : float
        Cost per step and per unit of force above ``force_soft_limit`` of the
        loader's limits (F_T / max_push_force and F_N / max_lift_force). Default 0.1.
    force_soft_limit : float
        Fraction of the loader's force limits where the excess-force cost
        starts. Default 0.8.
    """

    fill: float = 1.0
    energy: float = 1e-5
    validity: float = 0.01
    stall: float = 1.0
    force: float = 0.1
    force_soft_limit: float = 0.8

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, check_range(f"RewardWeights.{f.name}", getattr(self, f.name), 0.0))


def as_reward_weights(value: RewardWeights | Mapping[str, float] | None) -> RewardWeights:
    """Coerce ``None``, a mapping or :class:`RewardWeights`."""
    if value is None:
        return RewardWeights()
    if isinstance(value, RewardWeights):
        return value
    if isinstance(value, Mapping):
        unknown = sorted(set(value) - {f.name for f in fields(RewardWeights)})
        if unknown:
            raise ParameterError(f"reward_weights: unknown key(s) {unknown}")
        return RewardWeights(**value)
    raise ParameterError(f"reward_weights must be a RewardWeights or a dict, got {type(value).__name__}")


def _as_obj(value: Any, cls: type, name: str):
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        return cls.from_dict(dict(value))
    raise ParameterError(f"{name} must be a {cls.__name__} or a dict, got {type(value).__name__}")


def _positive(name: str, value: Any) -> float:
    return check_range(name, value, 0.0, low_open=True)


def _non_negative(name: str, value: Any) -> float:
    return check_range(name, value, 0.0)


def check_relax(value: Any, name: str = "relax") -> bool | float:
    """Validate a ``relax`` setting: a bool, or a repose angle in (0, pi/2) rad (returned as float)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    try:
        return check_range(name, value, 0.0, 0.5 * math.pi, low_open=True, high_open=True)
    except ParameterError:
        raise ParameterError(f"{name} must be a bool or a repose angle in (0, pi/2) rad, got {value!r}") from None


def _triple(name: str, value: Any, check: Any = check_finite) -> tuple[float, float, float]:
    try:
        values = tuple(value)
    except TypeError:
        values = ()
    if len(values) != 3:
        raise ParameterError(f"{name} must be an (x [m], z [m], blade_angle [rad]) triple, got {value!r}")
    return tuple(check(f"{name}[{i}]", v) for i, v in enumerate(values))


#: What the ``soil`` setting accepts (see :func:`~wheelloader.envs.soils.parse_soil`).
SoilArgument = str | SoilParams | SoilRandomization | Mapping[str, Any] | Sequence[str | SoilParams]


# ------------------------------------------------------------------ config
@dataclass(frozen=True, eq=False)
class EnvConfig:
    """All settings of a bucket-loading env: the one list of them, validated in ``__post_init__``.

    Both envs take these names as keyword arguments (:meth:`from_kwargs`); their signatures are built from
    this class (:func:`settings_parameters`). A field accepts what the env's docstring lists (e.g. a preset
    name for ``soil``, a dict for ``loader``) and holds the parsed value (a :class:`~wheelloader.estimator.
    SoilParams` or :class:`~wheelloader.envs.soils.SoilRandomization`, a :class:`Loader`, ...); the values
    derived from them are cached properties. :func:`dataclasses.replace` validates again.

    Parameters
    ----------
    soil : str, SoilParams, SoilRandomization, dict or list
        Hidden soil (default ``"gravel"``; ``"random"``: uniform over the presets).
    pile : Pile or dict, optional
        Start surface (default: 30 deg trapezoid, 1 m high).
    loader, bucket : Loader, Bucket or dict, optional
        Machine and bucket (defaults: the estimator's).
    control_rate : float
        Steps per second [Hz] (> 0).
    sensor_noise : float
        Std of the additive force noise [N] (>= 0).
    sensor_range : float
        Saturation of the force sensor [N] (> 0).
    reward_weights : RewardWeights or dict, optional
        Weights of the reward terms.
    truth : TruthOptions or dict, optional
        Effects beyond the model (all off by default).
    start_pose : (x, z, blade_angle), optional
        Start pose [m, m, rad] (default: 0.10 m before the pile toe, 0.03 m above the ground, -5 deg).
    start_noise : (x, z, blade_angle)
        Half-widths of the uniform start-pose noise [m, m, rad] (>= 0).
    blade_angle_limits : (low, high)
        Blade-angle range inside (-pi/2, pi/2) [rad].
    lift_headroom : float
        Workspace above the crest [m] (>= 0).
    max_tilt_acceleration : float
        Tilt-rate change limit [rad/s^2] (> 0).
    stall_patience : int
        Consecutive stalled steps that end the episode (>= 1).
    exit_clearance : float
        Clearance above the start surface that ends a cycle [m] (>= 0).
    exit_min_fill : float
        Fill needed (fraction of capacity, in [0, 1]) before a first exit ends a cycle.
    lookahead : sequence of float
        Look-ahead distances of the surface observations [m] (finite).
    slope_window : float
        Window of the local-slope estimate [m] (> 0).
    keep_pile : bool
        Start each episode on the carved pile of the previous cycle.
    relax : bool or float
        Relax a kept pile (True: to the soil's friction angle; a float: to that repose angle [rad]).
    relax_iterations : int
        Sweeps of :meth:`Pile.relaxed` per new cycle (>= 1).
    cycles_per_episode : int
        Digging cycles per episode (>= 1).
    force_model : str
        The plant's model, a name of :data:`~wheelloader.estimator.force_models.FORCE_MODELS` (env docstring).
    payload : PayloadOptions or dict, optional
        The payload of the payload models (default :func:`~wheelloader.estimator.force_models.check_force_model`'s).
    """

    soil: SoilArgument = "gravel"
    pile: Pile | Mapping[str, Any] | None = None
    loader: Loader | Mapping[str, Any] | None = None
    bucket: Bucket | Mapping[str, Any] | None = None
    control_rate: float = 60.0
    sensor_noise: float = 150.0
    sensor_range: float = 100_000.0
    reward_weights: RewardWeights | Mapping[str, float] | None = None
    truth: TruthOptions | Mapping[str, float] | None = None
    start_pose: Sequence[float] | None = None
    start_noise: Sequence[float] = DEFAULT_START_NOISE
    blade_angle_limits: Sequence[float] = DEFAULT_BLADE_ANGLE_LIMITS
    lift_headroom: float = 1.0
    max_tilt_acceleration: float = 4.0
    stall_patience: int = 1
    exit_clearance: float = 0.02
    exit_min_fill: float = 0.0
    lookahead: Sequence[float] = DEFAULT_LOOKAHEAD
    slope_window: float = 0.1
    keep_pile: bool = False
    relax: bool | float = False
    relax_iterations: int = 500
    cycles_per_episode: int = 1
    force_model: str = DEFAULT_FORCE_MODEL
    payload: PayloadOptions | Mapping[str, float] | None = None

    def __post_init__(self) -> None:
        set_ = functools.partial(object.__setattr__, self)
        set_("payload", check_force_model(self.force_model, as_payload(self.payload)))
        pile = parse_pile(self.pile)
        set_("soil", parse_soil(self.soil))
        set_("pile", pile)
        set_("loader", _as_obj(self.loader, Loader, "loader"))
        set_("bucket", _as_obj(self.bucket, Bucket, "bucket"))
        for name in ("control_rate", "sensor_range", "max_tilt_acceleration", "slope_window"):
            set_(name, _positive(name, getattr(self, name)))
        for name in ("sensor_noise", "lift_headroom", "exit_clearance"):
            set_(name, _non_negative(name, getattr(self, name)))
        set_("exit_min_fill", check_range("exit_min_fill", self.exit_min_fill, 0.0, 1.0))
        set_("reward_weights", as_reward_weights(self.reward_weights))
        set_("truth", as_truth(self.truth))
        set_("start_pose", _triple("start_pose", nominal_start_pose(pile) if self.start_pose is None
                                   else self.start_pose))
        set_("start_noise", _triple("start_noise", self.start_noise, _non_negative))
        angles = tuple(self.blade_angle_limits)
        if len(angles) != 2:
            raise ParameterError(f"blade_angle_limits must be (low, high), got {self.blade_angle_limits!r}")
        low = check_range("blade_angle_limits[0]", angles[0], -0.5 * math.pi, 0.5 * math.pi, low_open=True)
        high = check_range("blade_angle_limits[1]", angles[1], low, 0.5 * math.pi, low_open=True, high_open=True)
        set_("blade_angle_limits", (low, high))
        set_("lookahead", tuple(check_finite(f"lookahead[{i}]", v) for i, v in enumerate(self.lookahead)))
        for name in ("stall_patience", "relax_iterations", "cycles_per_episode"):
            set_(name, check_int(name, getattr(self, name)))
        if not isinstance(self.keep_pile, (bool, np.bool_)):
            raise ParameterError(f"keep_pile must be a bool, got {self.keep_pile!r}")
        set_("keep_pile", bool(self.keep_pile))
        set_("relax", check_relax(self.relax))

    @classmethod
    def from_kwargs(cls, owner: str = "EnvConfig", /, **settings: Any) -> EnvConfig:
        """The settings given as keyword arguments of an env (``owner`` names it in the error).

        Raises
        ------
        TypeError
            A keyword that is not a setting (as Python's message for an unknown keyword argument).
        ParameterError
            A bad value, naming the setting.
        """
        unknown = [name for name in settings if name not in SETTING_NAMES]
        if unknown:
            raise TypeError(f"{owner}() got an unexpected keyword argument {unknown[0]!r}; the settings are "
                            f"{list(SETTING_NAMES)}")
        return cls(**settings)

    # ------------------------------------------------------------------ derived values
    @functools.cached_property
    def model_options(self) -> ModelOptions:
        """The plant's force-model options (``"fee-payload"``: the carried load handed over at exit)."""
        return model_options_for(self.force_model, DEFAULT_OPTIONS)
    @functools.cached_property
    def dt(self) -> float:
        """Control period [s]."""
        return 1.0 / self.control_rate

    @functools.cached_property
    def x_limits(self) -> tuple[float, float]:
        """Workspace of the tip along x [m]: the pile grid."""
        return self.pile.x0, self.pile.x_end

    @functools.cached_property
    def z_limits(self) -> tuple[float, float]:
        """Workspace of the tip along z [m]: ground (lowest pile node) to crest + headroom."""
        return float(self.pile.heights.min()), float(self.pile.heights.max()) + self.lift_headroom

    @functools.cached_property
    def speed_step(self) -> float:
        """Largest change of a tip-velocity component per step, ``loader.max_acceleration * dt`` [m/s]."""
        return self.loader.max_acceleration * self.dt

    @functools.cached_property
    def tilt_rate_step(self) -> float:
        """Largest change of the tilt rate per step, ``max_tilt_acceleration * dt`` [rad/s]."""
        return self.max_tilt_acceleration * self.dt

    @functools.cached_property
    def exit_fill_volume(self) -> float:
        """``exit_min_fill`` as a volume [m^3]."""
        return self.exit_min_fill * self.bucket.capacity

    @functools.cached_property
    def motion(self) -> tuple:
        """What a step's kinematics reads, in one tuple: ``(dt, speed_step, tilt_rate_step, max_speed,
        max_tilt_rate, x_limits, z_limits, blade_angle_limits)``."""
        return (self.dt, self.speed_step, self.tilt_rate_step, self.loader.max_speed, self.loader.max_tilt_rate,
                self.x_limits, self.z_limits, self.blade_angle_limits)

    @functools.cached_property
    def truth_active(self) -> bool:
        """Whether an in-cycle effect beyond the model is on (``truth.active``)."""
        return self.truth.active

    @functools.cached_property
    def stone_decay(self) -> float:
        """Per-step decay factor of a stone spike (:func:`~wheelloader.envs.truth.stone_decay`)."""
        return stone_decay(self.truth, self.dt)

    @functools.cached_property
    def observation_limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of the observation, float32 arrays marked read-only (:meth:`obs_bounds`, computed once;
        the envs clip each observation to them)."""
        low, high = self.obs_bounds()
        low.flags.writeable = high.flags.writeable = False
        return low, high

    def obs_names(self) -> tuple[str, ...]:
        """Names of all observation entries."""
        return BASE_OBS_NAMES + tuple(f"surface_ahead_{i + 1}" for i in range(len(self.lookahead)))

    def obs_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(low, high) of the observation as float32 arrays."""
        x0, x1 = self.x_limits
        z0, z1 = self.z_limits
        a0, a1 = self.blade_angle_limits
        v, w = self.loader.max_speed, self.loader.max_tilt_rate
        half = 0.5 * math.pi
        f = self.sensor_range / 1000.0
        h0, h1 = float(self.pile.heights.min()), float(self.pile.heights.max())
        low = [x0, z0, a0, -v, -v, -w, 0.0, -half - a1, -half, 0.0, -f, -f] + [h0 - z1] * len(self.lookahead)
        high = [x1, z1, a1, v, v, w, z1 - z0, half - a0, half, 1.0, f, f] + [h1 - z0] * len(self.lookahead)
        return np.array(low, dtype=np.float32), np.array(high, dtype=np.float32)

    def to_dict(self) -> dict[str, Any]:
        """JSON-able summary (for cycle-log metadata; ``force_model`` and ``payload`` only when not ``"fee"``)."""
        model = {} if self.payload is None else {"force_model": self.force_model, "payload": self.payload.to_dict()}
        return {  # the paper's model adds nothing (saved metadata stays as it was)
            "soil": self.soil.to_dict(), "loader": self.loader.to_dict(), "bucket": self.bucket.to_dict(),
            "control_rate": self.control_rate, "sensor_noise": self.sensor_noise, "sensor_range": self.sensor_range,
            "reward": asdict(self.reward_weights), "truth": self.truth.to_dict(),
            "stall_patience": self.stall_patience, "exit_clearance": self.exit_clearance,
            "exit_min_fill": self.exit_min_fill, "keep_pile": self.keep_pile, "relax": self.relax,
            "relax_iterations": self.relax_iterations, "cycles_per_episode": self.cycles_per_episode, **model,
        }


#: The names of the env settings, in order (the fields of :class:`EnvConfig`).
SETTING_NAMES: tuple[str, ...] = tuple(f.name for f in fields(EnvConfig))


def settings_parameters() -> list[inspect.Parameter]:
    """The env settings as keyword-only parameters (names, defaults and annotations of :class:`EnvConfig`),
    for the envs' signatures."""
    return [inspect.Parameter(f.name, inspect.Parameter.KEYWORD_ONLY, default=f.default, annotation=f.type)
            for f in fields(EnvConfig)]


# ------------------------------------------------------------------ random draws (shared order)
def draw_start_pose(cfg: EnvConfig, rng: np.random.Generator) -> tuple[float, float, float]:
    """Start pose = ``start_pose`` + uniform noise of ``start_noise`` half-widths, clipped to the workspace."""
    u = rng.uniform(-1.0, 1.0, size=3)
    x0, x1 = cfg.x_limits
    z0, z1 = cfg.z_limits
    a0, a1 = cfg.blade_angle_limits
    x = min(max(cfg.start_pose[0] + cfg.start_noise[0] * float(u[0]), x0), x1)
    z = min(max(cfg.start_pose[1] + cfg.start_noise[1] * float(u[1]), z0), z1)
    a = min(max(cfg.start_pose[2] + cfg.start_noise[2] * float(u[2]), a0), a1)
    return x, z, a


def draw_noise_chunk(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Standard normals (sensor noise F_T, F_N) and uniforms (stone event, stone size) for NOISE_CHUNK steps."""
    return rng.standard_normal((NOISE_CHUNK, 2)), rng.random((NOISE_CHUNK, 2))


def choose_soil(cfg: EnvConfig, current: SoilParams | None, request: Any, rng: np.random.Generator) -> SoilParams:
    """The soil of a new cycle.

    ``request``: ``None`` (default: resample a distribution, keep a fixed soil
    with drift when ``truth.drift > 0``), ``"keep"`` (keep, with drift),
    ``"resample"`` (draw from the configured soil) or a soil spec (use it).
    """
    if request is None:
        request = "resample" if isinstance(cfg.soil, SoilRandomization) or current is None else "keep"
    if isinstance(request, str) and request in ("keep", "resample"):
        if request == "resample" or current is None:
            return cfg.soil.sample(rng) if isinstance(cfg.soil, SoilRandomization) else cfg.soil
        if cfg.truth.drift > 0.0:
            return drift_soil(current, cfg.truth.drift, rng)
        return current
    return as_soil(request)


def next_pile(cfg: EnvConfig, carved: Pile | None, keep: bool, relax: bool | float, soil: SoilParams) -> Pile:
    """Start surface of a new cycle: the configured pile, or the carved one (optionally relaxed).

    Relaxation runs at most ``cfg.relax_iterations`` sweeps of :meth:`Pile.relaxed` (area-conserving):
    steep carved walls slump toward the repose angle without paying for full convergence at every reset.
    """
    if not keep or carved is None:
        return cfg.pile
    if relax is False:
        return carved
    angle = soil.phi if relax is True else float(relax)
    angle = min(max(angle, math.radians(5.0)), math.radians(85.0))
    return carved.relaxed(angle, iterations=cfg.relax_iterations)
