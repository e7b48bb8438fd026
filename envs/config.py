"""Configuration shared by the single and the batched bucket-loading envs.

Both envs parse their keyword arguments here and draw their random numbers
through the helpers below in the same order, so that the same seed gives the
same trajectory in :class:`~wheelloader.envs.bucket_loading.BucketLoadingEnv`
and in :class:`~wheelloader.envs.vector.BucketLoadingVectorEnv`.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, fields
from typing import Any

import numpy as np

from wheelloader.estimator import (
    Bucket,
    Loader,
    ParameterError,
    Pile,
    SoilParams,
    as_soil,
)

from .soils import SoilRandomization, SoilSpec, drift_soil, parse_soil
from .truth import TruthOptions, as_truth

__all__ = ["BASE_OBS_NAMES", "BASE_OBS_UNITS", "DEFAULT_BLADE_ANGLE_LIMITS", "DEFAULT_LOOKAHEAD", "DEFAULT_START_NOISE",
           "NOISE_CHUNK", "REWARD_TERMS", "EnvConfig", "RewardWeights", "SoilRandomization", "SoilSpec",
           "as_reward_weights", "check_relax", "choose_soil", "draw_noise_chunk", "draw_start_pose", "drift_soil",
           "make_config", "next_pile", "nominal_start_pose", "parse_pile", "parse_soil", "pile_toe"]

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

#: Keys of the reward terms in ``info``; the reward is their sum in this order.
REWARD_TERMS: tuple[str, ...] = ("reward_fill", "reward_energy", "reward_validity", "reward_stall", "reward_force")


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
            value = getattr(self, f.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ParameterError(f"RewardWeights.{f.name} must be a finite number >= 0, got {value!r}")
            object.__setattr__(self, f.name, float(value))


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


# ------------------------------------------------------------------ pile
def parse_pile(pile: Any) -> Pile:
    """Parse the ``pile`` argument: ``None`` (default trapezoid), a :class:`Pile`, or a dict
    ``{"shape": "trapezoid" | "ideal_slope", **builder_kwargs}`` (angles in radians)."""
    if pile is None:
        return Pile.trapezoid()
    if isinstance(pile, Pile):
        return pile
    if isinstance(pile, Mapping):
        kwargs = dict(pile)
        shape = kwargs.pop("shape", "trapezoid")
        builders = {"trapezoid": Pile.trapezoid, "ideal_slope": Pile.ideal_slope}
        if shape not in builders:
            raise ParameterError(f"pile shape must be one of {sorted(builders)}, got {shape!r}")
        try:
            return builders[shape](**kwargs)
        except TypeError as exc:
            raise ParameterError(f"pile: bad arguments for {shape!r}: {exc}") from None
    raise ParameterError(f"pile must be None, a Pile or a dict, got {type(pile).__name__}")


def pile_toe(pile: Pile) -> float:
    """x of the pile toe: the last node before the surface first rises above its minimum [m]."""
    z = pile.heights
    rising = np.nonzero(z > z.min() + 1e-9)[0]
    first = int(rising[0]) if rising.size else 0
    return pile.x0 + pile.spacing * max(first - 1, 0)


def nominal_start_pose(pile: Pile) -> tuple[float, float, float]:
    """The env's default start pose on ``pile``: 0.10 m before the toe, 0.03 m above the ground, blade
    at -5 deg (x [m], z [m], blade angle [rad])."""
    return pile_toe(pile) - 0.10, float(pile.heights.min()) + 0.03, math.radians(-5.0)


def _as_obj(value: Any, cls: type, name: str):
    if value is None:
        return cls()
    if isinstance(value, cls):
        return value
    if isinstance(value, Mapping):
        return cls.from_dict(dict(value))
    raise ParameterError(f"{name} must be a {cls.__name__} or a dict, got {type(value).__name__}")


def _positive(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ParameterError(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)


def _non_negative(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
        raise ParameterError(f"{name} must be a finite number >= 0, got {value!r}")
    return float(value)


def check_relax(value: Any, name: str = "relax") -> bool | float:
    """Validate a ``relax`` setting: a bool, or a repose angle in (0, pi/2) rad (returned as float)."""
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if (isinstance(value, numbers.Real) and not isinstance(value, np.bool_) and math.isfinite(value)
            and 0.0 < value < 0.5 * math.pi):
        return float(value)
    raise ParameterError(f"{name} must be a bool or a repose angle in (0, pi/2) rad, got {value!r}")


def _fraction(name: str, value: Any) -> float:
    value = _non_negative(name, value)
    if value > 1.0:
        raise ParameterError(f"{name} must be a fraction in [0, 1], got {value!r}")
    return value


# ------------------------------------------------------------------ config
@dataclass(frozen=True, eq=False)
class EnvConfig:
    """All settings of a bucket-loading env, validated (see the env docstring for meanings)."""

    soil: SoilSpec
    pile: Pile
    loader: Loader
    bucket: Bucket
    control_rate: float
    sensor_noise: float
    sensor_range: float
    reward: RewardWeights
    truth: TruthOptions
    start_pose: tuple[float, float, float]
    start_noise: tuple[float, float, float]
    blade_angle_limits: tuple[float, float]
    lift_headroom: float
    max_tilt_acceleration: float
    stall_patience: int
    exit_clearance: float
    exit_min_fill: float
    lookahead: tuple[float, ...]
    slope_window: float
    keep_pile: bool
    relax: bool | float
    relax_iterations: int
    cycles_per_episode: int

    @property
    def dt(self) -> float:
        """Control period [s]."""
        return 1.0 / self.control_rate

    @property
    def x_limits(self) -> tuple[float, float]:
        """Workspace of the tip along x [m]: the pile grid."""
        return self.pile.x0, self.pile.x_end

    @property
    def z_limits(self) -> tuple[float, float]:
        """Workspace of the tip along z [m]: ground (lowest pile node) to crest + headroom."""
        return float(self.pile.heights.min()), float(self.pile.heights.max()) + self.lift_headroom

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
        """JSON-able summary (for cycle-log metadata)."""
        soil = self.soil.to_dict()
        return {
            "soil": soil, "loader": self.loader.to_dict(), "bucket": self.bucket.to_dict(),
            "control_rate": self.control_rate, "sensor_noise": self.sensor_noise, "sensor_range": self.sensor_range,
            "reward": asdict(self.reward), "truth": self.truth.to_dict(), "stall_patience": self.stall_patience,
            "exit_clearance": self.exit_clearance, "exit_min_fill": self.exit_min_fill, "keep_pile": self.keep_pile,
            "relax": self.relax,
            "relax_iterations": self.relax_iterations,
            "cycles_per_episode": self.cycles_per_episode,
        }


def make_config(
    *,
    soil: Any = "gravel",
    pile: Any = None,
    loader: Any = None,
    bucket: Any = None,
    control_rate: float = 60.0,
    sensor_noise: float = 150.0,
    sensor_range: float = 100_000.0,
    reward_weights: Any = None,
    truth: Any = None,
    start_pose: Sequence[float] | None = None,
    start_noise: Sequence[float] = DEFAULT_START_NOISE,
    blade_angle_limits: Sequence[float] = DEFAULT_BLADE_ANGLE_LIMITS,
    lift_headroom: float = 1.0,
    max_tilt_acceleration: float = 4.0,
    stall_patience: int = 1,
    exit_clearance: float = 0.02,
    exit_min_fill: float = 0.0,
    lookahead: Sequence[float] = DEFAULT_LOOKAHEAD,
    slope_window: float = 0.1,
    keep_pile: bool = False,
    relax: bool | float = False,
    relax_iterations: int = 500,
    cycles_per_episode: int = 1,
) -> EnvConfig:
    """Validate the env keyword arguments (shared by the single and the vector env)."""
    pile_obj = parse_pile(pile)
    rate = _positive("control_rate", control_rate)
    angles = tuple(float(a) for a in blade_angle_limits)
    if len(angles) != 2 or not (-0.5 * math.pi < angles[0] < angles[1] < 0.5 * math.pi):
        raise ParameterError(f"blade_angle_limits must be (low, high) inside (-pi/2, pi/2), got {blade_angle_limits!r}")
    if start_pose is None:
        start_pose = nominal_start_pose(pile_obj)
    pose = tuple(float(v) for v in start_pose)
    noise = tuple(_non_negative("start_noise", float(v)) for v in start_noise)
    if len(pose) != 3 or len(noise) != 3 or not all(math.isfinite(v) for v in pose):
        raise ParameterError("start_pose and start_noise must be (x [m], z [m], blade_angle [rad]) triples")
    look = tuple(float(v) for v in lookahead)
    if not all(math.isfinite(v) for v in look):
        raise ParameterError(f"lookahead distances must be finite, got {lookahead!r}")
    if isinstance(stall_patience, bool) or not isinstance(stall_patience, int) or stall_patience < 1:
        raise ParameterError(f"stall_patience must be an int >= 1, got {stall_patience!r}")
    if isinstance(relax_iterations, bool) or not isinstance(relax_iterations, int) or relax_iterations < 1:
        raise ParameterError(f"relax_iterations must be an int >= 1, got {relax_iterations!r}")
    if isinstance(cycles_per_episode, bool) or not isinstance(cycles_per_episode, int) or cycles_per_episode < 1:
        raise ParameterError(f"cycles_per_episode must be an int >= 1, got {cycles_per_episode!r}")
    relax = check_relax(relax)
    return EnvConfig(
        soil=parse_soil(soil), pile=pile_obj, loader=_as_obj(loader, Loader, "loader"),
        bucket=_as_obj(bucket, Bucket, "bucket"), control_rate=rate,
        sensor_noise=_non_negative("sensor_noise", sensor_noise),
        sensor_range=_positive("sensor_range", sensor_range), reward=as_reward_weights(reward_weights),
        truth=as_truth(truth), start_pose=pose, start_noise=noise, blade_angle_limits=angles,
        lift_headroom=_non_negative("lift_headroom", lift_headroom),
        max_tilt_acceleration=_positive("max_tilt_acceleration", max_tilt_acceleration),
        stall_patience=stall_patience, exit_clearance=_non_negative("exit_clearance", exit_clearance),
        exit_min_fill=_fraction("exit_min_fill", exit_min_fill),
        lookahead=look, slope_window=_positive("slope_window", slope_window), keep_pile=bool(keep_pile),
        relax=relax, relax_iterations=relax_iterations, cycles_per_episode=cycles_per_episode,
    )


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
