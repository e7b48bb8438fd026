#!/usr/bin/env bash
# Look-ahead against greedy over 10 cycles in the MPM plant (#33): the loop of benchmarks/loop_mpm.sh's ``ours``
# (held prior, kept objective with the transfer payload, descend clearance 0.1 m), the same piles and seeds, only
# plant_adaptation.py's --lookahead differs (planner/lookahead.py, ``True``: three candidates, each followed by the
# greedy plan of the next cycle). One soil x seed at a time, greedy first, then the look-ahead, so that a run cut
# short leaves whole pairs; resumable (every dug cycle is saved, xz, and read back when its plan is the same path).
#   * greedy's loops start from SEED_FROM's saved cycles where given (the v3 run's 5-cycle loops of ``ours``, dug
#     with the same settings: read back only where the plan made now is the same path; ``--stale error``);
#   * the look-ahead's loop starts from a copy of greedy's cycles of that pile: those its plans match (the same
#     path while it picks greedy's plan on the same pile) are read back, the others dug again (``--stale redig``).
# Then the two arms once more over every soil x seed (all resumed) into OUT/greedy and OUT/lookahead, and
# benchmarks/lookahead_mpm_report.py writes the table.
#
# Usage: bash benchmarks/lookahead_mpm.sh [OUT [CYCLES]] > run.log 2>&1
#   OUT     results (default docs/results/lookahead_mpm); CYCLES saved cycles (default data/results/lookahead_mpm/cycles)
#   PY      the Python to run (default python); SOILS (default "gravel sand"), SEEDS per soil (default 2)
#   RES, N  MPM grid spacing [m] and cycles per loop (defaults 0.02 and 10)
#   LANES   the plant's --threads (lanes; the results depend on it; default 2, as the v3 run)
#   TI_THREADS  the threads Taichi runs (--taichi-threads; default 1)
#   SEED_FROM   saved loops to start greedy from (e.g. data/results/loop_mpm_v3/cycles/loops; default none)
#   LOOKAHEAD   the look-ahead's setting: full (default; its arm ``lookahead``) or kept (KEPT_CANDIDATES, for the
#               kept objective: its arm ``lookahead_kept``)
#   FINAL       1 (default): the closing pass over every soil x seed into OUT/ARM; 0: none (the report reads the
#               parts)
set -euo pipefail
OUT=${1:-docs/results/lookahead_mpm}
CYCLES=${2:-data/results/lookahead_mpm/cycles}
PY=${PY:-python}
RES=${RES:-0.02}
N=${N:-10}
SOILS=${SOILS:-gravel sand}
SEEDS=${SEEDS:-2}
LOOKAHEAD=${LOOKAHEAD:-full}
case "$LOOKAHEAD" in full) ARM=lookahead; FLAG=(--lookahead) ;; kept) ARM=lookahead_kept; FLAG=(--lookahead kept) ;;
  *) echo "LOOKAHEAD must be full or kept, got $LOOKAHEAD" >&2; exit 2 ;; esac
COMMON=(--plant mpm --resolution "$RES" --threads "${LANES:-2}" --taichi-threads "${TI_THREADS:-1}" --ray off
        --cycles "$N" --failure-angle min_weight_force --heel-clearance 0 --end-blade-angle 55
        --curl-out-intervals 8 --midpoints off --objective kept_per_energy --prior held --descend-clearance 0.1
        --payload docs/results/transfer/transfer.json --strategies ours)
greedy() { "$PY" benchmarks/plant_adaptation.py "${COMMON[@]}" --stale error --cycles-dir "$CYCLES/greedy" "$@"; }
lookahead() { "$PY" benchmarks/plant_adaptation.py "${COMMON[@]}" "${FLAG[@]}" --stale redig \
    --cycles-dir "$CYCLES/$ARM" "$@"; }
copy_new() {  # copy_new SRC DST: the saved cycles of SRC that DST does not have
  mkdir -p "$2"
  for f in "$1"/cycle*.xz; do [ -e "$f" ] && { [ -e "$2/$(basename "$f")" ] || cp "$f" "$2/"; }; done; return 0
}
for soil in $SOILS; do
  for ((seed = 0; seed < SEEDS; seed++)); do
    echo "$soil seed $seed: greedy ($(date -u))"
    [ -n "${SEED_FROM:-}" ] && copy_new "$SEED_FROM/$soil/seed$seed/ours" "$CYCLES/greedy/$soil/seed$seed/ours"
    greedy --soils "$soil" --seeds $((seed + 1)) --out "$OUT/parts/greedy_${soil}_$seed"
    echo "$soil seed $seed: look-ahead $LOOKAHEAD ($(date -u))"
    copy_new "$CYCLES/greedy/$soil/seed$seed/ours" "$CYCLES/$ARM/$soil/seed$seed/ours"
    lookahead --soils "$soil" --seeds $((seed + 1)) --out "$OUT/parts/${ARM}_${soil}_$seed"
  done
done
if [ "${FINAL:-1}" = 1 ]; then
  echo "all: greedy and the look-ahead over every soil x seed (resumed) ($(date -u))"
  # shellcheck disable=SC2086
  greedy --soils $SOILS --seeds "$SEEDS" --out "$OUT/greedy"
  # shellcheck disable=SC2086
  lookahead --soils $SOILS --seeds "$SEEDS" --out "$OUT/$ARM"
fi
echo "done ($(date -u))"
