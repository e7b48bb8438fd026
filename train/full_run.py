"""The documented full run of the RL baseline (timings in train/README.md and the run's full_run.json).

1. PPO on the plant with randomised soils (domain randomisation);
2. PPO on the digital twin (one plant cycle with the Bezier path,
   calibrated soil), to be evaluated on the plant: fine-tuned from the
   domain-randomised policy (``ppo_twin``) and from scratch
   (``ppo_twin_scratch``);
3. SAC on the plant with randomised soils (small budget: SAC is several times
   slower per env-step than PPO on a CPU);
4. evaluation of all of them against the MPC planner (if available; the
   slowest part: ``--mpc-seeds`` gives it fewer seeds), the four fixed
   Bezier paths and a random policy on every soil preset and the same seeds.

Writes into ``--out`` (default ``train/results``): one folder per training
run (``model.zip``, ``config.json``, ``learning_curve.json``,
``train_summary.json``), ``evaluation.json``, ``evaluation.md``,
``learning_curve.png`` and ``full_run.json`` (stage timings, load).

Usage::

    python train/full_run.py --out train/results
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import evaluate
import ppo
import sac
from common import machine_info, write_json


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv`` and run the stages."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=Path("train/results"))
    parser.add_argument("--ppo-steps", type=int, default=600_000, help="PPO domain-randomisation env-steps")
    parser.add_argument("--twin-steps", type=int, default=200_000,
                        help="PPO digital-twin fine-tuning env-steps (from the domain-randomised policy)")
    parser.add_argument("--twin-scratch-steps", type=int, default=500_000,
                        help="PPO digital-twin env-steps from scratch (0: skip)")
    parser.add_argument("--plant-soil", default="lean_clay", help="hidden soil of the twin set-up's plant")
    parser.add_argument("--sac-steps", type=int, default=50_000, help="SAC domain-randomisation env-steps (0: skip)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--eval-seeds", default="2000-2004", help="evaluation env seeds")
    parser.add_argument("--mpc-seeds", default="same",
                        help="evaluation env seeds of the MPC planner only, e.g. 2000-2001 (default 'same': "
                             "--eval-seeds); the MPC is the slowest policy by far")
    parser.add_argument("--soils", default="all", help="evaluation soils")
    parser.add_argument("--torch-threads", type=int, default=1)
    parser.add_argument("--progress-bar", action=argparse.BooleanOptionalAction, default=False)
    args = parser.parse_args(argv)
    out: Path = args.out
    common = ["--seed", str(args.seed), "--torch-threads", str(args.torch_threads), "--checkpoint-freq", "0",
              "--eval-freq", "50000", "--progress-bar" if args.progress_bar else "--no-progress-bar"]
    stages: dict[str, dict] = {}
    t_all = time.perf_counter()

    def stage(name: str, func, stage_args: list[str]) -> None:
        load0 = os.getloadavg()
        t0 = time.perf_counter()
        print(f"== {name}: {' '.join(stage_args)}", flush=True)
        func(stage_args)
        stages[name] = {"args": stage_args, "wall_s": time.perf_counter() - t0, "loadavg_before": list(load0),
                        "loadavg_after": list(os.getloadavg())}
        write_json(out / "full_run.json", {"machine": machine_info(), "stages": stages,
                                           "wall_s": time.perf_counter() - t_all})

    stage("ppo_randomized", ppo.main, ["--setup", "randomized", "--total-timesteps", str(args.ppo_steps),
                                       "--out", str(out / "ppo_randomized"), *common])
    twin = ["--setup", "twin", "--plant-soil", args.plant_soil]
    stage("ppo_twin", ppo.main, [*twin, "--init-model", str(out / "ppo_randomized" / "model.zip"),
                                 "--total-timesteps", str(args.twin_steps), "--out", str(out / "ppo_twin"), *common])
    models = ["--ppo", str(out / "ppo_randomized" / "model.zip"), "--ppo", str(out / "ppo_twin" / "model.zip")]
    if args.twin_scratch_steps > 0:
        stage("ppo_twin_scratch", ppo.main, [*twin, "--total-timesteps", str(args.twin_scratch_steps),
                                             "--out", str(out / "ppo_twin_scratch"), *common])
        models += ["--ppo", str(out / "ppo_twin_scratch" / "model.zip")]
    if args.sac_steps > 0:
        stage("sac_randomized", sac.main, ["--setup", "randomized", "--total-timesteps", str(args.sac_steps),
                                           "--out", str(out / "sac_randomized"), *common])
        models += ["--sac", str(out / "sac_randomized" / "model.zip")]
    if args.mpc_seeds != "same":
        models += ["--mpc-seeds", args.mpc_seeds]
    stage("evaluate", evaluate.main, [*models, "--soils", args.soils, "--seeds", args.eval_seeds,
                                      "--torch-threads", str(args.torch_threads), "--out", str(out)])
    print(f"full run: {time.perf_counter() - t_all:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
