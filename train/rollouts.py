"""Evaluation of policies on the plant: one episode's metrics, summaries, every policy on every soil and seed."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from common import ENV_ID
from policies import Policy

import wheelloader.envs  # noqa: F401  (registers the env ids)


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
