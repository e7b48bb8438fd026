"""Why the demo's cycle-2 prediction misses by 80 %, and what fitting only the identifiable parameters does to it.

``wheelloader demo`` (the FEE env plant, 3 seeds, 5 cycles) calibrates the soil after each cycle (varpro,
warm-started) and predicts the next cycle. This script reruns it with the calibration's options changed, and
nothing else:

* ``default``: the demo as it is;
* ``held``: ``CalibrationOptions(held=HeldPrior(...))`` with the Sobol rule's held set
  (``benchmarks/sensitivity.py``: gamma, K and n) fixed at the demo's nominal soil (the ``sand`` preset the
  demo starts from), cohesion, adhesion, phi and delta fitted;
* ``soft``: the same held parameters under a Gaussian prior at the nominal soil (gamma 10 %, K 30 %, n 0.15);
* ``regularize``: ``CalibrationOptions(regularize=True)`` (the weak prior at the warm start).

It replaces the name ``CalibrationOptions`` in ``wheelloader.adaptation`` (what the demo's ``Calibrating``
strategy calls) by one with these settings; the demo's code is unchanged.

Run: ``python benchmarks/demo_identify.py --mode held --out /tmp/demo_held`` (about a minute of CPU per mode;
prints the demo's table and writes the demo's outputs into ``--out``).
"""

from __future__ import annotations

import argparse
import functools
from pathlib import Path

import wheelloader.adaptation as adaptation
from wheelloader.demo import run_demo
from wheelloader.estimator import preset
from wheelloader.estimator.calibration import CalibrationOptions, HeldPrior
from wheelloader.estimator.soil_vector import SOIL_VECTOR_NAMES, soil_vector

MODES = ("default", "held", "soft", "regularize")
FREE = ("cohesion", "adhesion", "phi", "delta")


def options_for(mode: str):
    """The ``CalibrationOptions`` factory of a mode."""
    nominal = preset(adaptation.NOMINAL_SOIL)
    mean = dict(zip(SOIL_VECTOR_NAMES, soil_vector(nominal, 0.02).tolist(), strict=True))
    if mode == "held":
        return functools.partial(CalibrationOptions, held=HeldPrior(mean, free_one=FREE))
    if mode == "soft":
        std = {"gamma": 0.1 * mean["gamma"], "K": 0.3 * mean["K"], "n": 0.15}
        return functools.partial(CalibrationOptions, held=HeldPrior(mean, std=std, free_one=FREE))
    if mode == "regularize":
        return functools.partial(CalibrationOptions, regularize=True)
    return CalibrationOptions


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mode", choices=MODES, default="held")
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--out", type=Path, required=True, help="output folder (the demo's figures and summary)")
    args = parser.parse_args()
    adaptation.CalibrationOptions = options_for(args.mode)
    args.out.mkdir(parents=True, exist_ok=True)
    print(run_demo(args.out, seeds=args.seeds)["table"])


if __name__ == "__main__":
    main()
