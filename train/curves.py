"""Learning curves: the evaluation callback of a training run and the plot of several runs."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from common import write_json
from policies import SB3Policy
from rollouts import run_episode, summarize
from stable_baselines3.common.callbacks import BaseCallback


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

    @property
    def eval_time(self) -> float:
        """Wall time spent in the learning-curve evaluations so far [s]."""
        return self._eval_time

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
