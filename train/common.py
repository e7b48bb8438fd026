"""Shared pieces of the SB3 training and evaluation scripts (not a library module).

The scripts in ``train/`` import this file as ``common`` (Python puts the
script's folder first on ``sys.path``); it imports only the installed
``wheelloader`` package, Gymnasium, NumPy, stable-baselines3 and torch.

Contents
--------
* :class:`BatchedVecEnv`: adapter from the NumPy-batched Gymnasium vector env
  (``gym.make_vec(..., vectorization_mode="vector_entry_point")``) to SB3's
  :class:`~stable_baselines3.common.vec_env.VecEnv` API (same-step
  auto-reset, ``terminal_observation`` and ``TimeLimit.truncated`` in the
  infos, as SB3 expects);
* :func:`make_train_env`: the training VecEnv (batched, or SB3's DummyVecEnv
  over single envs), wrapped in ``VecMonitor``;
* the two training set-ups: domain randomisation over the soil presets, and
  the digital twin (one plant cycle with the Bezier path, calibrated soil);
* baseline policies (random, fixed Bezier path tracking, the MPC planner if
  installed) and SB3 models behind one ``reset()`` / ``act(obs)`` interface;
* :func:`evaluate`: run policies on the same seeds and soils and collect
  fill, energy, energy per m^3, stalls and constraint violations;
* :class:`LearningCurveCallback` and :func:`plot_learning_curves`.
"""

from __future__ import annotations

import argparse
import json
import math
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecMonitor

import wheelloader.envs  # noqa: F401  (registers the env ids)
from wheelloader.estimator import PRESET_NAMES, SoilParams, as_soil, paper_paths
from wheelloader.provenance import machine_info

#: The env trained and evaluated on (one digging cycle, 600 steps at 60 Hz).
ENV_ID = "wheelloader/BucketLoading-v0"
#: Soil used as "the plant" of the digital-twin set-up by default.
DEFAULT_PLANT_SOIL = "lean_clay"
#: Set-ups of the training scripts.
SETUPS = ("randomized", "twin")


# ------------------------------------------------------------------ machine, threads, json
def set_torch_threads(threads: int) -> int:
    """Set torch's intra-op threads (1 by default: small MLPs gain nothing from more on a shared 2-core CPU)."""
    import torch

    if threads < 1:
        raise ValueError(f"--torch-threads must be >= 1, got {threads!r}")
    torch.set_num_threads(threads)
    return torch.get_num_threads()


def jsonable(value: Any) -> Any:
    """Convert NumPy scalars/arrays, SoilParams and non-finite floats (-> None) for ``json.dump``."""
    if isinstance(value, dict):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, SoilParams):
        return value.to_dict()
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def write_json(path: Path, data: Any) -> None:
    """Write ``data`` as indented JSON (creates the folder)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(jsonable(data), indent=2) + "\n")


# ------------------------------------------------------------------ SB3 adapter of the batched env
class BatchedVecEnv(VecEnv):
    """SB3 ``VecEnv`` over the NumPy-batched bucket-loading vector env (one process, no copies per env).

    The Gymnasium vector env auto-resets in ``NEXT_STEP`` mode (the step after
    an episode end only resets). SB3 expects ``SAME_STEP`` semantics: the
    observation returned with ``done=True`` is already the first one of the
    next episode and the final one is in ``info["terminal_observation"]``.
    This adapter resets finished sub-envs right away, with the same random
    draws the vector env would make one step later, so sub-env ``i`` still
    follows the single env seeded with ``seed + i``.

    Parameters
    ----------
    env_id : str
        A registered id with a vector entry point.
    n_envs : int
        Number of sub-envs.
    env_kwargs : dict
        Keyword arguments of the env.
    """

    def __init__(self, env_id: str, n_envs: int, env_kwargs: dict[str, Any] | None = None) -> None:
        self.venv = gym.make_vec(env_id, num_envs=n_envs, vectorization_mode="vector_entry_point",
                                 **(env_kwargs or {}))
        base = self.venv.unwrapped
        missing = [a for a in ("_reset_env", "_observation", "_prev_done", "_steps") if not hasattr(base, a)]
        if missing:
            raise RuntimeError(f"{type(base).__name__} lacks {missing}: the batched adapter cannot reset single "
                               "sub-envs; use --vec dummy")
        super().__init__(n_envs, self.venv.single_observation_space, self.venv.single_action_space)
        self._actions: np.ndarray | None = None
        self._seeded = False

    def reset(self) -> np.ndarray:
        seeds = self._seeds
        seed = None if all(s is None for s in seeds) else [None if s is None else int(s) for s in seeds]
        obs, _ = self.venv.reset(seed=seed)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=np.float32).reshape(self.num_envs, -1)

    def step_wait(self):
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        done = terminated | truncated
        fill = info.get("fill_fraction")
        stalled = info.get("stalled")
        infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        if done.any():
            base = self.venv.unwrapped
            for i in np.nonzero(done)[0]:
                i = int(i)
                infos[i]["terminal_observation"] = obs[i].copy()
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
                if fill is not None:
                    infos[i]["fill_fraction"] = float(fill[i])
                if stalled is not None:
                    infos[i]["stalled"] = bool(stalled[i])
                base._reset_env(i, {})  # what the vector env would do at the next step (NEXT_STEP mode)
                base._steps[i] = 0
                base._prev_done[i] = False
            obs = base._observation()
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices=None) -> list[Any]:
        value = getattr(self.venv.unwrapped, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.venv.unwrapped, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list[Any]:
        result = getattr(self.venv.unwrapped, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        return [None for _ in range(self.num_envs)]


def make_train_env(env_kwargs: dict[str, Any], n_envs: int, seed: int, vec: str = "batched") -> VecEnv:
    """The training VecEnv: ``"batched"`` (:class:`BatchedVecEnv`) or ``"dummy"`` (SB3 DummyVecEnv of
    ``gym.make`` envs), wrapped in ``VecMonitor`` (episode returns for the logs), seeded with
    ``seed`` (sub-env ``i`` gets ``seed + i``)."""
    if n_envs < 1:
        raise ValueError(f"--n-envs must be >= 1, got {n_envs!r}")
    if vec == "batched":
        env: VecEnv = BatchedVecEnv(ENV_ID, n_envs, env_kwargs)
    elif vec == "dummy":
        env = DummyVecEnv([lambda: gym.make(ENV_ID, **env_kwargs) for _ in range(n_envs)])
    else:
        raise ValueError(f"--vec must be 'batched' or 'dummy', got {vec!r}")
    env.seed(seed)
    return VecMonitor(env)


# ------------------------------------------------------------------ set-ups
def resolve_setup(setup: str, plant_soil: str, seed: int, out: Path | None = None) -> dict[str, Any]:
    """Env keyword arguments and a JSON-able description of a training set-up.

    ``"randomized"``: the plant with the hidden soil drawn uniformly from the
    soil presets at every reset (domain randomisation).
    ``"twin"``: one cycle on the plant (soil ``plant_soil``, seed ``seed``)
    with the reference Bezier path; its logged cycle is calibrated with
    ``wheelloader.estimator.calibrate`` and the policy is trained on the env
    running the calibrated parameters (the digital twin), to be evaluated on
    the plant. The cycle log is saved under ``out`` if given.
    """
    if setup == "randomized":
        return {"env_kwargs": {"soil": "random"},
                "description": {"setup": setup, "soil": "uniform over presets", "presets": list(PRESET_NAMES)}}
    if setup != "twin":
        raise ValueError(f"--setup must be one of {SETUPS}, got {setup!r}")
    calibrate = load_calibrate()
    if calibrate is None:
        raise RuntimeError("set-up 'twin' needs wheelloader.estimator.calibrate, which is not available")
    from wheelloader.envs.config import pile_toe
    from wheelloader.envs.scripted import run_path

    plant = gym.make(ENV_ID, soil=as_soil(plant_soil))
    path = paper_paths(pile_toe(plant.unwrapped.cfg.pile))[0]
    run = run_path(plant, path, seed=seed)
    log = plant.unwrapped.last_cycle_log()
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        log.save(out / "plant_cycle.csv", overwrite=True)
    t0 = time.perf_counter()
    cal = calibrate(log)
    cal_time = time.perf_counter() - t0
    params = cal.params
    truth = as_soil(plant_soil)
    desc = {
        "setup": setup, "plant_soil": plant_soil, "plant_params": truth.to_dict(),
        "calibrated_params": params.to_dict(), "calibration_time_s": cal_time,
        "calibration_success": bool(getattr(cal, "success", True)),
        "plant_cycle": {"path": path.name, "seed": seed, "fill_fraction": run["fill_fraction"],
                        "steps": run["steps"], "stalled": run["stalled"]},
    }
    return {"env_kwargs": {"soil": params}, "description": desc}


def load_calibrate() -> Callable | None:
    """``wheelloader.estimator.calibrate`` if the estimator provides it, else None."""
    try:
        from wheelloader.estimator import calibrate
    except ImportError:
        try:
            from wheelloader.estimator.calibration import calibrate
        except ImportError:
            return None
    return calibrate


# ------------------------------------------------------------------ policies behind one interface
class Policy:
    """A controller for evaluation: ``reset(seed)`` at the start of an episode, then ``act(obs)``."""

    name = "policy"

    def reset(self, seed: int, env: gym.Env) -> None:  # noqa: B027 - optional hook
        """Start of an episode (``env`` is the evaluation env after its reset)."""

    def act(self, obs: np.ndarray) -> np.ndarray:
        raise NotImplementedError


class RandomPolicy(Policy):
    """Uniform random actions in [-1, 1]^3, seeded per episode."""

    name = "random"

    def __init__(self) -> None:
        self._rng = np.random.default_rng(0)

    def reset(self, seed: int, env: gym.Env) -> None:
        self._rng = np.random.default_rng(seed)

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self._rng.uniform(-1.0, 1.0, 3).astype(np.float32)


class PathPolicy(Policy):
    """A fixed bucket path (the paper's Fig. 8 paths) tracked with ``wheelloader.envs.scripted.PathTracker``."""

    def __init__(self, index: int) -> None:
        self.index = index
        self.name = f"bezier_path{index + 1}"
        self._tracker = None

    def reset(self, seed: int, env: gym.Env) -> None:
        from wheelloader.envs.config import pile_toe
        from wheelloader.envs.scripted import PathTracker

        cfg = env.unwrapped.cfg
        path = paper_paths(pile_toe(cfg.pile), rate=cfg.control_rate)[self.index]
        self._tracker = PathTracker(path, cfg.loader, cfg.control_rate)

    def act(self, obs: np.ndarray) -> np.ndarray:
        return self._tracker(obs)


class SB3Policy(Policy):
    """A trained SB3 model, deterministic actions."""

    def __init__(self, model: Any, name: str) -> None:
        self.model = model
        self.name = name

    def act(self, obs: np.ndarray) -> np.ndarray:
        action, _ = self.model.predict(obs, deterministic=True)
        return action


def load_sb3(path: str | Path, name: str | None = None) -> SB3Policy:
    """Load ``model.zip`` (PPO or SAC, read from the run's ``config.json`` or guessed) with SB3's ``load``."""
    from stable_baselines3 import PPO, SAC

    path = Path(path)
    algo = None
    cfg_file = path.parent / "config.json"
    if cfg_file.exists():
        algo = json.loads(cfg_file.read_text()).get("algo")
    if algo is None:
        algo = "sac" if "sac" in path.as_posix().lower() else "ppo"
    cls = {"ppo": PPO, "sac": SAC}[algo.lower()]
    model = cls.load(path, device="cpu")
    return SB3Policy(model, name or f"{algo.lower()}:{path.parent.name}")


def mpc_policy() -> Policy | None:
    """The MPC planner of ``wheelloader.planner`` as a policy, or None if the planner offers none."""
    try:
        import wheelloader.planner as planner
    except ImportError:
        return None
    factory = getattr(planner, "make_env_policy", None) or getattr(planner, "MPCPolicy", None)
    if factory is None:
        return None
    return _PlannerPolicy(factory)


class _PlannerPolicy(Policy):
    """Wraps a planner controller ``factory(env) -> callable(obs) -> action``, built at every reset."""

    name = "mpc"

    def __init__(self, factory: Callable) -> None:
        self._factory = factory
        self._ctrl = None

    def reset(self, seed: int, env: gym.Env) -> None:
        self._ctrl = self._factory(env.unwrapped)
        if hasattr(self._ctrl, "reset"):
            self._ctrl.reset()

    def act(self, obs: np.ndarray) -> np.ndarray:
        ctrl = self._ctrl
        out = ctrl.act(obs) if hasattr(ctrl, "act") else ctrl(obs)
        return np.asarray(out, dtype=np.float32)


# ------------------------------------------------------------------ evaluation
def run_episode(policy: Policy, soil: Any, seed: int, env_kwargs: dict[str, Any] | None = None) -> dict[str, Any]:
    """One episode of ``policy`` on the plant with hidden ``soil`` and env seed ``seed``.

    Returns return, fill (fraction and m^3), energy [J] (work on soil plus
    payload lifting), stall (episode ended by a stall), stalled steps,
    validity violations (steps in soil outside the force model's validity
    domain), force-limit violations (steps above the soft force limit), steps
    and whether the cycle completed (tip exited the pile).
    """
    kwargs = dict(env_kwargs or {})
    kwargs["soil"] = soil
    env = gym.make(ENV_ID, **kwargs)
    obs, _ = env.reset(seed=seed)
    policy.reset(seed, env)
    total, steps = 0.0, 0
    stalled_steps = validity = force = 0
    info: dict[str, Any] = {}
    terminated = truncated = False
    while not (terminated or truncated):
        obs, reward, terminated, truncated, info = env.step(policy.act(obs))
        total += float(reward)
        steps += 1
        stalled_steps += int(bool(info["stalled"]))
        validity += int(info["reward_validity"] < 0.0)
        force += int(info["reward_force"] < 0.0)
    env.close()
    energy = float(info["energy_soil"] + info["energy_payload"])
    fill = float(info["fill_volume"])
    return {
        "return": total, "fill_fraction": float(info["fill_fraction"]), "fill_volume_m3": fill,
        "energy_J": energy, "energy_per_m3_J": energy / fill if fill > 1e-6 else None,
        "stall": bool(terminated and info["stalled"]), "stalled_steps": stalled_steps,
        "validity_violations": validity, "force_limit_violations": force, "steps": steps,
        "cycle_completed": bool(info.get("cycle_done", False)), "truncated": bool(truncated),
    }


def summarize(episodes: list[dict[str, Any]]) -> dict[str, Any]:
    """Means over episodes; energy per m^3 as total energy / total fill (robust to empty buckets)."""
    if not episodes:
        return {}
    out: dict[str, Any] = {"episodes": len(episodes)}
    for key in ("return", "fill_fraction", "fill_volume_m3", "energy_J", "stalled_steps", "validity_violations",
                "force_limit_violations", "steps"):
        vals = np.array([e[key] for e in episodes], dtype=float)
        out[key] = float(vals.mean())
        out[key + "_std"] = float(vals.std())
    fill = sum(e["fill_volume_m3"] for e in episodes)
    out["energy_per_m3_J"] = sum(e["energy_J"] for e in episodes) / fill if fill > 1e-6 else None
    out["stall_rate"] = float(np.mean([e["stall"] for e in episodes]))
    out["completion_rate"] = float(np.mean([e["cycle_completed"] for e in episodes]))
    return out


def evaluate(policies: Sequence[Policy], soils: Sequence[str], seeds: Sequence[int],
             env_kwargs: dict[str, Any] | None = None, progress: bool = False,
             seeds_by_policy: dict[str, Sequence[int]] | None = None) -> dict[str, Any]:
    """Every policy on every (soil, seed) pair; per-soil and overall summaries plus the raw episodes.

    ``seeds_by_policy`` overrides ``seeds`` for the named policies (e.g. fewer
    seeds for the slow MPC planner).
    """
    results: dict[str, Any] = {}
    for policy in policies:
        t0 = time.perf_counter()
        per_soil: dict[str, Any] = {}
        every: list[dict[str, Any]] = []
        for soil in soils:
            eps = []
            for seed in (seeds_by_policy or {}).get(policy.name, seeds):
                ep = run_episode(policy, soil, int(seed), env_kwargs)
                ep.update(soil=soil, seed=int(seed))
                eps.append(ep)
            per_soil[soil] = summarize(eps)
            every.extend(eps)
        results[policy.name] = {"overall": summarize(every), "per_soil": per_soil, "episodes": every,
                                "eval_time_s": time.perf_counter() - t0}
        if progress:
            s = results[policy.name]["overall"]
            print(f"  {policy.name:>24}: return {s['return']:7.3f}  fill {s['fill_fraction']:.3f}  "
                  f"energy {s['energy_J']:8.0f} J  stalls {s['stall_rate']:.2f}", flush=True)
    return results


# ------------------------------------------------------------------ learning curve
class LearningCurveCallback(BaseCallback):
    """Every ``eval_freq`` env-steps: deterministic evaluation on fixed soils and seeds (held-out seeds),
    plus the mean training episode return of the recent episodes; saved to ``learning_curve.json``."""

    def __init__(self, out: Path, eval_freq: int, soils: Sequence[str], seeds: Sequence[int],
                 env_kwargs: dict[str, Any] | None = None, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.out = out
        self.eval_freq = int(eval_freq)
        self.soils, self.seeds = list(soils), list(seeds)
        self.env_kwargs = dict(env_kwargs or {})
        self.records: list[dict[str, Any]] = []
        self._next = 0
        self._t0 = time.perf_counter()
        self._eval_time = 0.0

    def _on_training_start(self) -> None:
        self._t0 = time.perf_counter()
        self._next = self.num_timesteps
        self._evaluate()

    def _on_step(self) -> bool:
        if self.eval_freq > 0 and self.num_timesteps >= self._next:
            self._evaluate()
        return True

    def _on_training_end(self) -> None:
        if not self.records or self.records[-1]["timesteps"] != self.num_timesteps:
            self._evaluate()

    def _evaluate(self) -> None:
        t0 = time.perf_counter()
        policy = SB3Policy(self.model, "current")
        eps = [run_episode(policy, soil, seed, self.env_kwargs) for soil in self.soils for seed in self.seeds]
        self._eval_time += time.perf_counter() - t0
        s = summarize(eps)
        buf = [ep["r"] for ep in (self.model.ep_info_buffer or [])]
        rec = {"timesteps": int(self.num_timesteps), "wall_s": time.perf_counter() - self._t0,
               "eval_time_s": self._eval_time,
               "train_return": float(np.mean(buf)) if buf else None,
               "eval_return": s["return"], "eval_fill_fraction": s["fill_fraction"], "eval_energy_J": s["energy_J"],
               "eval_stall_rate": s["stall_rate"]}
        self.records.append(rec)
        self._next = self.num_timesteps + self.eval_freq
        for key in ("eval_return", "eval_fill_fraction", "eval_energy_J"):
            self.logger.record(f"curve/{key}", rec[key])
        write_json(self.out / "learning_curve.json", {"soils": self.soils, "seeds": self.seeds,
                                                      "records": self.records})
        if self.verbose:
            print(f"[{rec['timesteps']:>9d} steps] eval return {rec['eval_return']:.3f} "
                  f"fill {rec['eval_fill_fraction']:.3f} energy {rec['eval_energy_J']:.0f} J", flush=True)


def plot_learning_curves(curves: dict[str, dict[str, Any]], path: Path,
                         baselines: dict[str, dict[str, Any]] | None = None) -> None:
    """Learning curves (eval return and fill vs env-steps) of several runs, with baseline levels, to PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 5.2))
    for name, curve in curves.items():
        recs = curve["records"]
        steps = [r["timesteps"] for r in recs]
        label = name
        if curve.get("soils"):
            label += f" (curve: {', '.join(curve['soils'])}; {len(curve.get('seeds', []))} held-out seeds)"
        axes[0].plot(steps, [r["eval_return"] for r in recs], marker=".", label=label)
        axes[1].plot(steps, [r["eval_fill_fraction"] for r in recs], marker=".", label=name)
    styles = ["--", ":", "-."]
    for k, (name, summary) in enumerate((baselines or {}).items()):
        ls = styles[k % len(styles)]
        axes[0].axhline(summary["return"], color="gray", ls=ls, lw=1, label=name)
        axes[1].axhline(summary["fill_fraction"], color="gray", ls=ls, lw=1, label=name)
    axes[0].set(xlabel="env-steps of the run", ylabel="eval return (deterministic)", title="Episode return")
    axes[1].set(xlabel="env-steps of the run", ylabel="bucket fill / capacity", title="Fill", ylim=(0, 1.05))
    for ax in axes:
        ax.grid(alpha=0.3)
        ax.set_xlim(left=0)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.045 * math.ceil(len(labels) / 2), 1, 1))
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ------------------------------------------------------------------ argparse helpers
def int_list(text: str) -> list[int]:
    """``"0,1,2"`` or ``"0-4"`` -> list of ints."""
    text = text.strip()
    if "-" in text and "," not in text and not text.startswith("-"):
        lo, hi = (int(v) for v in text.split("-", 1))
        return list(range(lo, hi + 1))
    return [int(v) for v in text.split(",") if v.strip()]


def str_list(text: str) -> list[str]:
    """Comma-separated names; ``"all"`` = every soil preset."""
    if text.strip().lower() == "all":
        return list(PRESET_NAMES)
    names = [v.strip() for v in text.split(",") if v.strip()]
    for n in names:
        as_soil(n)  # validates (ParameterError names the bad preset)
    return names


def weights(text: str) -> dict[str, float]:
    """``"stall=0.2,validity=0.001"`` -> dict (validated by the env's RewardWeights)."""
    from wheelloader.envs import RewardWeights

    out: dict[str, float] = {}
    for item in text.split(","):
        if item.strip():
            key, _, value = item.partition("=")
            out[key.strip()] = float(value)
    RewardWeights(**out)
    return out


def add_training_args(parser: argparse.ArgumentParser, default_steps: int, default_envs: int) -> None:
    """Arguments shared by ppo.py and sac.py."""
    parser.add_argument("--setup", choices=SETUPS, default="randomized",
                        help="randomized: plant with soils drawn from the presets; twin: calibrated digital twin")
    parser.add_argument("--plant-soil", default=DEFAULT_PLANT_SOIL,
                        help=f"hidden soil of the plant cycle for --setup twin (default {DEFAULT_PLANT_SOIL})")
    parser.add_argument("--total-timesteps", type=int, default=default_steps, help="env-steps to train")
    parser.add_argument("--n-envs", type=int, default=default_envs, help="parallel sub-envs")
    parser.add_argument("--vec", choices=("batched", "dummy"), default="batched",
                        help="batched NumPy vector env (default) or SB3 DummyVecEnv of single envs")
    parser.add_argument("--seed", type=int, default=0, help="seed of the envs, the policy and the twin's plant cycle")
    parser.add_argument("--out", type=Path, default=None, help="output directory (default results/<algo>_<setup>)")
    parser.add_argument("--torch-threads", type=int, default=1, help="torch intra-op threads (default 1)")
    parser.add_argument("--progress-bar", action=argparse.BooleanOptionalAction, default=True,
                        help="show SB3's progress bar (needs tqdm and rich)")
    parser.add_argument("--tensorboard", action="store_true", help="write TensorBoard logs to OUT/tb")
    parser.add_argument("--checkpoint-freq", type=int, default=100_000,
                        help="save a checkpoint every this many env-steps (0: none)")
    parser.add_argument("--eval-freq", type=int, default=50_000,
                        help="learning-curve evaluation every this many env-steps (0: only start and end)")
    parser.add_argument("--eval-soils", type=str_list, default="gravel,sand,lean_clay,fat_clay",
                        help="soils of the learning-curve evaluation ('all' = every preset)")
    parser.add_argument("--eval-seeds", type=int_list, default="1000-1001",
                        help="env seeds of the learning-curve evaluation (held out from training)")
    parser.add_argument("--init-model", type=Path, default=None,
                        help="start from this saved model (same algorithm), e.g. fine-tune a domain-randomised "
                             "policy on the digital twin; its hyperparameters are kept")
    parser.add_argument("--reward-weights", type=weights, default=None,
                        help="training reward weights, e.g. 'stall=0.2,validity=0.001' (RewardWeights fields; "
                             "default: the env's). Evaluations always use the env's default reward")
    parser.add_argument("--verbose", type=int, default=0, help="SB3 verbosity")


def train(algo: str, args: argparse.Namespace, model_kwargs: dict[str, Any]) -> dict[str, Any]:
    """Train ``algo`` ("ppo" or "sac") with the parsed ``args``; writes into ``args.out``:

    ``model.zip`` (load with ``PPO.load``/``SAC.load``), ``config.json``,
    ``learning_curve.json``, ``train_summary.json``, ``checkpoints/``,
    ``tb/`` (with ``--tensorboard``), ``plant_cycle.csv`` (twin set-up).
    """
    from stable_baselines3 import PPO, SAC
    from stable_baselines3.common.callbacks import CallbackList, CheckpointCallback

    if args.total_timesteps < 1:
        raise ValueError(f"--total-timesteps must be >= 1, got {args.total_timesteps!r}")
    out: Path = args.out or Path("results") / f"{algo}_{args.setup}"
    out.mkdir(parents=True, exist_ok=True)
    threads = set_torch_threads(args.torch_threads)
    setup = resolve_setup(args.setup, args.plant_soil, args.seed, out)
    env_kwargs = dict(setup["env_kwargs"])
    if args.reward_weights:
        env_kwargs["reward_weights"] = dict(args.reward_weights)
    eval_soils = [args.plant_soil] if args.setup == "twin" else list(args.eval_soils)
    env = make_train_env(env_kwargs, args.n_envs, args.seed, args.vec)
    cls = {"ppo": PPO, "sac": SAC}[algo]
    tb = str(out / "tb") if args.tensorboard else None
    if args.init_model is not None:
        model = cls.load(args.init_model, env=env, device="cpu", verbose=args.verbose, tensorboard_log=tb)
        model.set_random_seed(args.seed)
        model_kwargs = {"init_model": str(args.init_model), "loaded_hyperparameters": True}
    else:
        model = cls("MlpPolicy", env, seed=args.seed, device="cpu", verbose=args.verbose, tensorboard_log=tb,
                    **model_kwargs)
    config = {"algo": algo, "env_id": ENV_ID, "setup": setup["description"], "args": vars(args),
              "model_kwargs": model_kwargs, "torch_threads": threads, "machine": machine_info()}
    write_json(out / "config.json", config)
    curve = LearningCurveCallback(out, args.eval_freq, eval_soils, args.eval_seeds, verbose=1)
    callbacks = [curve]
    if args.checkpoint_freq > 0:
        callbacks.append(CheckpointCallback(max(args.checkpoint_freq // args.n_envs, 1), str(out / "checkpoints"),
                                            name_prefix=algo))
    load0 = machine_info()["loadavg_1_5_15min"]
    t0 = time.perf_counter()
    model.learn(total_timesteps=args.total_timesteps, callback=CallbackList(callbacks),
                progress_bar=args.progress_bar, tb_log_name=f"{algo}_{args.setup}")
    wall = time.perf_counter() - t0
    model.save(out / "model.zip")
    env.close()
    steps = int(model.num_timesteps)
    summary = {
        "algo": algo, "setup": args.setup, "timesteps": steps, "wall_s": wall,
        "learning_curve_eval_s": curve._eval_time,
        "env_steps_per_s": steps / wall, "env_steps_per_s_excluding_curve_eval": steps / max(wall - curve._eval_time,
                                                                                             1e-9),
        "loadavg_before": load0, "loadavg_after": machine_info()["loadavg_1_5_15min"],
        "final_eval": curve.records[-1] if curve.records else None, "model": str(out / "model.zip"),
    }
    write_json(out / "train_summary.json", summary)
    print(f"{algo.upper()} {args.setup}: {steps} env-steps in {wall:.1f} s "
          f"({summary['env_steps_per_s_excluding_curve_eval']:.0f} env-steps/s without curve evaluations); "
          f"model -> {out / 'model.zip'}", flush=True)
    return summary
