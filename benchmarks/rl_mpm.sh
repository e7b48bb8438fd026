#!/usr/bin/env bash
# #33 item 3: the trained policies in the MPM plant beside the planners (docs/results/rl_mpm.md). Both policies
# (trained in the FEE env's default model, and with force_model="fee-payload"), each open loop (rl_path: its path in
# the FEE env of the nominal soil replayed in the plant) and closed loop (rl_closed: acting on the plant's state every
# control step), on the acceptance run's loops (loop_mpm.sh: same settings, soils, seeds, start pile). Resumable:
# every dug cycle is saved and read back when the same command runs again.
#
# Usage: nice -n 5 bash benchmarks/rl_mpm.sh > run.log 2>&1
#   PY       the Python to run (default python); RES, N, SEEDS: MPM grid [m], cycles per loop, seeds (0.02, 5, 1)
#   OUT      loop_mpm.sh's results (default docs/results/loop_mpm); CYCLES its saved cycles
#            (default data/results/loop_mpm/cycles)
#   POLICY1  the FEE-env policy (default OUT/policy/model.zip: train/ppo.py --setup randomized
#            --total-timesteps 300000); its open-loop loops are loop_mpm.sh's RL_POLICY phase (OUT/rl)
#   POLICY2  the fee-payload policy (default OUT/rl_payload/policy/model.zip; its command in its config.json)
#   FEE_CYCLES  the FEE env plant's saved cycles of loop_mpm.md's gap table (default data/results/loop_mpm/fee_env_cycles)
# Writes OUT/rl_closed (the FEE-env policy closed loop), OUT/rl_payload/{rl,rl_closed,fee_env_rl} (the fee-payload
# policy), OUT/rl_gap/acceptance.{md,json,png} (the table) and saved cycles under CYCLES/loops/SOIL/seedN/rl_closed
# and CYCLES/rl_payload.
#   STEPS    which steps to run (default "1 2 3 4 5")
#   STALE    what a saved cycle dug along another plan gets (plant_adaptation.py --stale: error, redig, keep;
#            default error)
set -euo pipefail
PY=${PY:-python}
RES=${RES:-0.02}
N=${N:-5}
SEEDS=${SEEDS:-1}
OUT=${OUT:-docs/results/loop_mpm}
CYCLES=${CYCLES:-data/results/loop_mpm/cycles}
POLICY1=${POLICY1:-$OUT/policy/model.zip}
POLICY2=${POLICY2:-$OUT/rl_payload/policy/model.zip}
FEE_CYCLES=${FEE_CYCLES:-data/results/loop_mpm/fee_env_cycles}
P2OUT=$OUT/rl_payload
P2CYCLES=$CYCLES/rl_payload
STEPS=${STEPS:-1 2 3 4 5}
SETTINGS=(--cycles "$N" --failure-angle min_weight_force --heel-clearance 0 --end-blade-angle 55 --curl-out-intervals 8
          --midpoints off --objective kept_per_energy --ray off --soils gravel sand)
mpm() { "$PY" benchmarks/plant_adaptation.py --plant mpm --resolution "$RES" --threads 2 --stale "${STALE:-error}" \
    --seeds "$SEEDS" "${SETTINGS[@]}" "$@"; }
for step in $STEPS; do
  case $step in
    1) echo "1: the FEE-env policy closed loop in the plant ($(date -u))"
       mpm --strategies rl_closed --rl-policy "$POLICY1" --cycles-dir "$CYCLES/loops" --out "$OUT/rl_closed" ;;
    2) echo "2: the fee-payload policy's path replayed in the plant ($(date -u))"
       mpm --strategies rl_path --rl-policy "$POLICY2" --cycles-dir "$P2CYCLES/loops" --out "$P2OUT/rl" ;;
    3) echo "3: the fee-payload policy closed loop in the plant ($(date -u))"
       mpm --strategies rl_closed --rl-policy "$POLICY2" --cycles-dir "$P2CYCLES/loops" --out "$P2OUT/rl_closed" ;;
    4) echo "4: the fee-payload policy's path in the FEE env plant (the gap table's left side) ($(date -u))"
       "$PY" benchmarks/plant_adaptation.py --plant fee-env --seeds 2 "${SETTINGS[@]}" --strategies rl_path \
           --rl-policy "$POLICY2" --cycles-dir "$P2CYCLES/fee_env" --out "$P2OUT/fee_env_rl" ;;
    5) echo "5: the table ($(date -u))"
       "$PY" benchmarks/loop_mpm_report.py --out "$OUT" --cycles "$CYCLES" --fee "$OUT/fee_env" "$OUT/fee_env_rl" \
           --fee-cycles "$FEE_CYCLES" --policy fee-payload "$P2OUT" "$P2CYCLES" \
           --write "$OUT/rl_gap" ;;
    *) echo "unknown step $step" >&2; exit 2 ;;
  esac
done
echo "done ($(date -u))"
