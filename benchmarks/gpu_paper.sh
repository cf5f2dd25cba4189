#!/usr/bin/env bash
# The paper-size pipeline on every GPU of one machine, as one background job:
#   1. the paper dataset (depth + RGB) and the real-like evaluation set;
#   2. Table 1's simulation-split networks (four columns x seven fabrics), as a
#      queue of small tasks the GPUs pull from, longest first; meanwhile one
#      GPU trains PhySNet-depth for gray interlock alone and times one estimate
#      with it after compile (benchmarks/estimate_latency.py);
#   3. Tables 2 and 3 for the four methods in the same run: every recording x
#      method in lockstep, SHARDS_PER_GPU processes per GPU (contiguous chunks
#      by set, so each process simulates few meshes per step);
#   4. the tables, Table 1 and the similarity maps; then, while time is left,
#      the random-split runs of Table 1's k-NN column.
#   setsid bash benchmarks/gpu_paper.sh /tmp/run >/tmp/run.log 2>&1 &
# COLUMNS=physnet_depth,sdn_depth: only those methods (no RGB frames then);
# RANDOM_SPLIT=0: skip the random-split runs at the end.
# NOISE=1: the training dataset's depth frames go through the sensor model
# (BENCHMARKS.md: on the demo's size this removed the need for it on candidates).
# Progress: $R/status.txt. Every step resumes: rerun after an interruption.
# Training defaults: at most EPOCHS epochs, the epoch chosen on VAL of the
# training simulations, stopping after PATIENCE epochs without a better one.
# A CPU smoke run of the scheduling (tiny data, fake GPUs):
#   NG=2 SMOKE=1 bash benchmarks/gpu_paper.sh /tmp/gp_smoke
set -uo pipefail
R=${1:-/tmp/run}
. "$(dirname "$0")/gpu_lib.sh"  # FABRICS, NG, T1_ARGS, COLUMNS (and SMOKE versions)
SHARDS_PER_GPU=${SHARDS_PER_GPU:-2}
LATENCY=${LATENCY:-1}
RANDOM_SPLIT=${RANDOM_SPLIT:-1}
DS_ARGS="--batch_size=210"
EVAL_ARGS="--sequences=3"
EST_ARGS="--preset=paper"  # the paper's protocol (argmin); the posterior is the default preset
if [ -n "${SMOKE:-}" ]; then  # tiny everything, MuJoCo C, for checking this script on a CPU
  DS_ARGS="--preset=smoke --sequences=10 --materials=gray_interlock,black_denim"
  EVAL_ARGS="--preset=smoke"
  EST_ARGS="--preset=smoke --backend=c"
fi
[[ $COLUMNS == *rgb* ]] && DS_ARGS="$DS_ARGS --rgb"
[ "${NOISE:-0}" = 1 ] && DS_ARGS="$DS_ARGS --noise"  # train on sensor-model frames
T1="python -m experiments.table1 --dataset=$R/ds --workdir=$R/t1 $T1_ARGS --train_only"
note "start: $NG GPUs; columns $COLUMNS; table1 $T1_ARGS"

make_queue simulation >"$R/queue/simulation.txt"
if [ "$RANDOM_SPLIT" = 1 ]; then make_queue random; fi >"$R/queue/random.txt"
lane() {
  local g=$1
  case $g in
    0) step "$g" dataset 600 python -m experiments.generate_dataset --out="$R/ds" $DS_ARGS \
         && touch "$R/ds.done" ;;
    1) step "$g" eval_set 600 python -m experiments.make_eval_set --out="$R/eval" $EVAL_ARGS \
         && touch "$R/eval.done" ;;
  esac
  wait_for "$R/ds.done"
  if [ "$g" -eq $((NG - 1)) ] && [ "$NG" -gt 1 ] && [ "$LATENCY" = 1 ]; then  # alone on its GPU
    local gi=${FABRICS[1]}
    step "$g" t1_latency_net 900 $T1 --columns=physnet_depth --splits=simulation --materials="$gi"
    wait_for "$R/eval.done"
    step "$g" latency 900 python benchmarks/estimate_latency.py \
      --recording="$R/eval/fabrics/$gi/0000" --material="$gi" $EST_ARGS \
      --model="$R/t1/physnet_depth/simulation/$gi" --out="$R/latency.json" \
      --settings=default,q8_warmup0.5
  fi
  drain "$g" simulation 1500
  all_ended simulation
  wait_for "$R/eval.done"
  local s pids=()
  # XLA's share leaves a fifth of the GPU to Warp's graphs (a shard died of a Warp
  # out-of-memory error at 0.9 when another job joined its GPU).
  for ((s = g * SHARDS_PER_GPU; s < (g + 1) * SHARDS_PER_GPU; s++)); do
    XLA_PYTHON_CLIENT_MEM_FRACTION=$(awk "BEGIN { print 0.8 / $SHARDS_PER_GPU }") \
      step "$g" "tables_shard$s" 1500 python -m experiments.tables --eval="$R/eval" \
      --models="$R/t1" --workdir="$R/tables" --methods="$COLUMNS" --shard="$s" \
      --num_shards=$((NG * SHARDS_PER_GPU)) $EST_ARGS &
    pids+=($!)
  done
  wait "${pids[@]}"
  touch "$R/estimates_gpu$g.done"
  if [ "$g" -eq 0 ]; then
    for ((s = 0; s < NG; s++)); do wait_for "$R/estimates_gpu$s.done"; done
    step 0 tables 600 python -m experiments.tables --eval="$R/eval" --models="$R/t1" \
      --workdir="$R/tables" --methods="$COLUMNS" $EST_ARGS
    step 0 table1 900 python -m experiments.table1 --dataset="$R/ds" --workdir="$R/t1" \
      $T1_ARGS --columns="$COLUMNS" --splits=simulation
    touch "$R/tables.done"
  fi
  drain "$g" random 1500
}

for ((g = 0; g < NG; g++)); do lane "$g" & done
wait
[ "$RANDOM_SPLIT" = 1 ] && step 0 table1_all 900 python -m experiments.table1 \
  --dataset="$R/ds" --workdir="$R/t1" $T1_ARGS --columns="$COLUMNS"
note "all done"
touch "$R/all.done"
