#!/usr/bin/env bash
# The loop judged in the MPM plant (#33 acceptance): fixed Bezier path, ours (greedy plan, kept objective) and
# the hindsight oracle, gravel and sand x 2 seeds x 5 cycles, and the fixed path dug on every pile ours started
# a cycle from (paired). One process at a time, resumable: every dug cycle is saved (xz) and read back when the
# same command runs again. The phases run in this order, so that a run cut short leaves whole comparisons
# (the paired ones first; the folders keep their numbers):
#   1 seed 0 of both soils: ours' loops and the fixed path on their piles (the paired comparison);
#   3 seed 1: ours and the fixed path on its piles;
#   2 seed 0: the hindsight oracle, its parameters fitted to the soil's seed-0 cycles of ours;
#   4 the fixed path's own loops (their first cycle is the paired one on the untouched pile, copied);
#   5 every seed: the oracle with its parameters fitted to all of the soil's cycles (fixed and ours: phase 2's
#     loops are dug again where the refit changes their plans).
# Then benchmarks/loop_mpm_report.py writes the acceptance table from the phases' JSONs and the saved cycles.
#
# Usage: nice -n 5 bash benchmarks/loop_mpm.sh [OUT [CYCLES]] > run.log 2>&1
#   OUT     results (default docs/results/loop_mpm); CYCLES saved cycles (default data/results/loop_mpm/cycles)
#   PY      the Python to run (default python)
#   RES, N  MPM grid spacing [m] and cycles per loop (defaults 0.02 and 5; the smoke test: RES=0.06 N=2)
#   PRIOR   ours' calibration prior (plant_adaptation.py --prior: none, nominal or held; default none)
#   DESCEND the planner's --descend-clearance [m] (the tip moves down only this near the surface; default off)
#   PAYLOAD the kept objective's payload (--payload JSON, e.g. docs/results/transfer/transfer.json; default off)
#   TI_THREADS  the threads Taichi runs (--taichi-threads; default: the lanes, 2); the lanes stay 2
#   FORCE_MODEL ours' force model (--force-model: fee, fee-payload, fee-payload-depth or fee-learned; default fee)
#   RL_POLICY  a PPO model.zip (train/ppo.py): after phase 2, its path (rolled out in the FEE env of the
#           nominal soil on each pile, adaptation.PolicyPath) dug in the plant, seed 0 of both soils (OUT/rl)
set -euo pipefail
OUT=${1:-docs/results/loop_mpm}
CYCLES=${2:-data/results/loop_mpm/cycles}
PY=${PY:-python}
RES=${RES:-0.02}
N=${N:-5}
PRIOR=${PRIOR:-none}
TI=(${TI_THREADS:+--taichi-threads "$TI_THREADS"})
COMMON=(--plant mpm --resolution "$RES" --threads 2 "${TI[@]}" --ray off --cycles "$N" --failure-angle min_weight_force
        --heel-clearance 0 --end-blade-angle 55 --curl-out-intervals 8 --midpoints off
        --objective kept_per_energy --stale error --prior "$PRIOR" --force-model "${FORCE_MODEL:-fee}"
        ${DESCEND:+--descend-clearance "$DESCEND"} ${PAYLOAD:+--payload "$PAYLOAD"})
adapt() { "$PY" benchmarks/plant_adaptation.py "${COMMON[@]}" --cycles-dir "$CYCLES/loops" "$@"; }
paired() { "$PY" benchmarks/plant_paired.py --plant mpm --resolution "$RES" --threads 2 "${TI[@]}" --ray off \
    --cycles "$CYCLES/loops" --cycles-dir "$CYCLES/paired" --out "$OUT/paired"; }
echo "phase 1: seed 0, gravel and sand: ours, then the fixed path on its piles ($(date -u))"
adapt --soils gravel sand --seeds 1 --strategies ours --out "$OUT/phase1"
paired
echo "phase 3: seed 1: ours, then the fixed path on its piles ($(date -u))"
adapt --soils gravel sand --seeds 2 --strategies ours --out "$OUT/phase3"
paired
echo "phase 2: seed 0: the hindsight oracle fitted to ours' seed-0 cycles ($(date -u))"
adapt --soils gravel sand --seeds 1 --strategies ours oracle --out "$OUT/phase2"
if [ -n "${RL_POLICY:-}" ]; then
  echo "phase 2b: seed 0: the trained policy's paths ($(date -u))"
  adapt --soils gravel sand --seeds 1 --strategies rl_path --rl-policy "$RL_POLICY" --out "$OUT/rl"
fi
echo "phase 4: the fixed path's loops ($(date -u))"
for soil in gravel sand; do
  for seed in 0 1; do
    src="$CYCLES/paired/$soil/seed$seed/fixed_on_ours/cycle1"
    dst="$CYCLES/loops/$soil/seed$seed/fixed"
    mkdir -p "$dst"
    for f in cycle1.csv.xz cycle1.json.xz; do [ -e "$dst/$f" ] || cp "$src/$f" "$dst/$f"; done
  done
done
adapt --soils gravel sand --seeds 2 --strategies fixed ours --out "$OUT/phase4"
echo "phase 5: the hindsight oracle fitted to all cycles ($(date -u))"
adapt --soils gravel sand --seeds 2 --strategies fixed ours oracle --out "$OUT/loops"
echo "done ($(date -u))"
