"""Speed of the force model: a vectorised 281-sample evaluation and a single-sample evaluation.

Usage::

    python benchmarks/model_speed.py --out results/model_speed

Writes ``model_speed.json`` with median timings (targets on a 2-core machine:
<= 1 ms vectorised, <= 20 us single sample).
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from pathlib import Path

from wheelloader.estimator import Bucket, Pile, contact_state, default_path, preset, soil_forces, soil_forces_single
from wheelloader.provenance import machine_info


def _median_time(fn, repeats: int, inner: int) -> float:
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        for _ in range(inner):
            fn()
        samples.append((time.perf_counter() - start) / inner)
    return statistics.median(samples)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="results/model_speed", help="output directory")
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--soil", default="gravel")
    args = parser.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    soil, bucket, pile, path = preset(args.soil), Bucket(), Pile.trapezoid(), default_path()
    state = contact_state(path.x, path.z, path.blade_angle, pile, bucket)
    w_load = state.load_weight(soil.gamma)
    vector = _median_time(lambda: soil_forces(soil, state, bucket), args.repeats, 50)
    kin = _median_time(lambda: contact_state(path.x, path.z, path.blade_angle, pile, bucket), args.repeats, 5)
    i = int(state.depth.argmax())
    args_single = (soil, state.depth[i], state.rho[i], state.alpha[i], state.blade_length[i], float(w_load[i]), bucket)
    args_single = tuple(float(a) if not isinstance(a, (type(soil), type(bucket))) else a for a in args_single)
    single = _median_time(lambda: soil_forces_single(*args_single), args.repeats, 2000)
    result = {
        "benchmark": "model_speed",
        "soil": args.soil,
        "samples": len(path),
        "vectorised_median_s": vector,
        "single_sample_median_s": single,
        "kinematics_with_carving_median_s": kin,
        "targets": {"vectorised_s": 1e-3, "single_sample_s": 20e-6},
        "meets_targets": {"vectorised": vector <= 1e-3, "single_sample": single <= 20e-6},
        "machine": machine_info(),
    }
    (out / "model_speed.json").write_text(json.dumps(result, indent=2))
    print(f"vectorised {len(path)}-sample force evaluation: {vector * 1e6:8.1f} us (target <= 1000 us)")
    print(f"single-sample force evaluation:            {single * 1e6:8.2f} us (target <= 20 us)")
    print(f"kinematics incl. carving ({len(path)} samples):  {kin * 1e3:8.2f} ms")
    print(f"wrote {out / 'model_speed.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
