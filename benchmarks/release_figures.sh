#!/usr/bin/env bash
# Re-measure the speed figures the README and docs/real.md quote, this checkout against a previous release, in the
# order and pairing the docs describe (not run by pytest; about 15 minutes on a quiet 2-core machine: 13 before the
# locksteps ran in both roles, pass bch88, which adds ≈ 1.5 min).
#
#   git worktree add --detach /some/where/prev <previous release>
#   bash benchmarks/release_figures.sh /some/where/prev OUT_DIR [DATA_DIR]
#
# OUT_DIR receives (a = this checkout, b = the previous release):
#   ab_1.txt, ab_2.txt      lockstep thread CPU per scan and stage, core 0 (docs/real.md "Where it stands");
#                           the first pair runs beside a real table, the second alone with the cache warm
#   real_{a,b}{1,2,3}/      bench_real.py tables on core 1 (docs/real.md "Today's figures": run 3 is the quiet one,
#                           runs 1-2 had the lockstep or bench_pipeline on the other core)
#   pipe_{a,b}.txt          bench_pipeline.py on core 0 beside a real table (README "Speed": this slot's figures;
#                           the table comes from side-by-side pairs, this release and the previous one at once)
#   mit_{a,b}{1,2}.txt      MIT CSAIL in wall time, core 1 (1: with bench_memory on core 0, 2: alone)
#   mem_{a,b}.txt           bench_memory.py peak RSS on MIT CSAIL (README memory sentence)
#   comp_{a,b}{1,2}.txt     cold compile wait of the README's first command (needs chrt, i.e. root)
#   result_columns.txt      md5 of each table's result columns (every column but the four speed ones): all six
#                           must agree when the two releases are bit-identical
#   slam.txt                bench_slam.py --markdown of this checkout, core 0, alone after the last lockstep: the
#                           SLAM core alone on sim:static and MIT CSAIL, ending with docs/slam.md "Speed"'s table
#                           rows, its command line and the load (paste the rows there)
#
#   ab_1s.txt, ab_2s.txt    the same locksteps in the other role: the previous release's own bench_pipeline_ab.py
#                           with --other this checkout (one run per input, --reps 1: ≈ 1 min each; ab_1s fills the
#                           wait for the real tables on core 1, ab_2s runs alone after ab_2)
#   ab_roles_{1,2}.txt      both roles side by side per input and stage (benchmarks/ab_roles.py): new / previous
#                           with the new release as "this", as "other", and their geometric mean, in which the
#                           roles' bias (≈ 2-4 %) cancels; quote the geometric means of ab_roles_2
#
# The workers' warm-up compiles every kernel signature benchmarks/run_kernels.json records (kernelwarm.preload)
# that numba's cache does not hold, so a lockstep right after a change to a kernel module no longer compiles the
# kernels first called after the warm-up inside its first input (ab_1's first row, before pass bch88); each row
# says how many kernels were loaded or compiled inside the measured runs (0 expected).
#
# Environment: RELEASE_INPUTS (space-separated bench_digest.py names) replaces the lockstep inputs,
# RELEASE_AB_ONLY=1 runs only the four locksteps and the role tables (a check of this script: with
# RELEASE_INPUTS="sim:drive" about 2 minutes).
set -euo pipefail
if [ $# -lt 2 ] || [ ! -d "$1/src/dynslam2d" ]; then
  echo "usage: bash benchmarks/release_figures.sh PREV_CHECKOUT OUT_DIR [DATA_DIR]" \
       "(PREV_CHECKOUT: a checkout of the previous release, with src/dynslam2d)" >&2
  exit 2
fi
PREV=$(cd "$1" && pwd)
OUT=$(mkdir -p "$2" && cd "$2" && pwd)
REPO=$(cd "$(dirname "$0")/.." && pwd)
DATA=${3:-$REPO/../shared/data}
DATA=$(cd "$DATA" && pwd)
MIT=$DATA/mit-csail/mit-csail.clf
read -r -a INPUTS <<< "${RELEASE_INPUTS:-negative_2/right negative_2/left negative_2/rear positive_1 overtakes mit-csail sim:drive}"
cd "$REPO"
export PYTHONPATH=$REPO/src

real() {  # real <checkout> <name>
  (cd "$1" && PYTHONPATH=$1/src taskset -c 1 python benchmarks/bench_real.py --data "$DATA" --cpu 1 \
     --out "$OUT/$2" --table "$OUT/$2/table.md" > "$OUT/$2.log" 2>&1)
}
mit() {  # mit <src> <file>
  PYTHONPATH=$1 taskset -c 1 python benchmarks/bench_real_speed.py --data "$DATA" --only mit-csail --reps 3 > "$OUT/$2" 2>&1
}

ab() {  # ab <n>: the lockstep, new release as "this" (2 runs per input), then as "other" (the previous release's
        # own script, 1 run per input; left out when the previous release has no bench_pipeline_ab.py)
  taskset -c 0 python benchmarks/bench_pipeline_ab.py "${INPUTS[@]}" --data "$DATA" --other "$PREV/src" --reps 2 \
    > "$OUT/ab_$1.txt" 2>&1
  if [ -f "$PREV/benchmarks/bench_pipeline_ab.py" ]; then
    (cd "$PREV" && PYTHONPATH=$PREV/src taskset -c 0 python benchmarks/bench_pipeline_ab.py "${INPUTS[@]}" \
       --data "$DATA" --other "$REPO/src" --reps 1 > "$OUT/ab_$1s.txt" 2>&1)
    python benchmarks/ab_roles.py "$OUT/ab_$1.txt" "$OUT/ab_$1s.txt" > "$OUT/ab_roles_$1.txt"
  fi
}

uptime > "$OUT/load.txt"
if [ "${RELEASE_AB_ONLY:-0}" = 1 ]; then
  ab 1
  ab 2
  uptime >> "$OUT/load.txt"
  cat "$OUT"/ab_roles_*.txt 2> /dev/null || true
  exit 0
fi
ab 1 &
P=$!
real "$REPO" real_a1
real "$PREV" real_b1
wait $P
real "$REPO" real_a2 &
P=$!
taskset -c 0 python benchmarks/bench_pipeline.py > "$OUT/pipe_a.txt" 2>&1
(cd "$PREV" && PYTHONPATH=$PREV/src taskset -c 0 python benchmarks/bench_pipeline.py > "$OUT/pipe_b.txt" 2>&1)
wait $P
real "$PREV" real_b2
mit "$REPO/src" mit_a1.txt &
P=$!
taskset -c 0 python benchmarks/bench_memory.py --inputs "$MIT" > "$OUT/mem_a.txt" 2>&1
wait $P
mit "$PREV/src" mit_b1.txt &
P=$!
taskset -c 0 python benchmarks/bench_memory.py --src "$PREV/src" --inputs "$MIT" > "$OUT/mem_b.txt" 2>&1
wait $P
if command -v chrt > /dev/null && chrt -f 1 true 2> /dev/null; then
  for i in 1 2; do
    chrt -f 1 python benchmarks/bench_compile.py --wait > "$OUT/comp_a$i.txt" 2>&1
    chrt -f 1 python benchmarks/bench_compile.py --wait --src "$PREV/src" > "$OUT/comp_b$i.txt" 2>&1
  done
else
  echo "chrt -f 1 not allowed here: cold compile waits not measured" > "$OUT/comp_skipped.txt"
fi
real "$REPO" real_a3
real "$PREV" real_b3
mit "$PREV/src" mit_b2.txt
mit "$REPO/src" mit_a2.txt
ab 2
taskset -c 0 python benchmarks/bench_slam.py --markdown > "$OUT/slam.txt" 2>&1
uptime >> "$OUT/load.txt"
for t in "$OUT"/real_*/table.md; do
  printf '%s ' "$(basename "$(dirname "$t")")"
  grep '^|' "$t" | awk -F'|' '{for(i=2;i<=NF-4;i++) printf "%s|",$i; print ""}' | md5sum | cut -c1-32
done > "$OUT/result_columns.txt"
cat "$OUT/result_columns.txt"
cat "$OUT"/ab_roles_2.txt 2> /dev/null || true
