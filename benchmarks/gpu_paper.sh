#!/usr/bin/env bash
# The paper-size pipeline on every GPU of one machine, as one background job:
#   1. the paper dataset (depth + RGB) and the real-like evaluation set, each
#      one process whose worlds are split over every GPU;
#   2. Table 1's simulation-split networks (four columns x seven fabrics) as one
#      program in NG processes joined by jax.distributed (experiments.launch),
#      each training its share; then one estimate timed after compile
#      (benchmarks/estimate_latency.py);
#   3. Tables 2 and 3 for the four methods: the same way, each process its
#      share of recording x method in lockstep; process 0 writes the tables;
#   4. the random-split runs of Table 1's k-NN column.
#   setsid bash benchmarks/gpu_paper.sh /tmp/run >/tmp/run.log 2>&1 &
# COLUMNS=physnet_depth,sdn_depth: only those methods (no RGB frames then);
# RANDOM_SPLIT=0: skip the random-split runs at the end.
# NOISE=1: the training dataset's depth frames go through the sensor model
# (BENCHMARKS.md: on the demo's size this removed the need for it on candidates).
# Progress: $R/status.txt. Every step resumes: rerun after an interruption.
# Training defaults: at most EPOCHS epochs, the epoch chosen on VAL of the
# training simulations, stopping after PATIENCE epochs without a better one.
# A CPU smoke run of the script (tiny data, NG processes on the CPU):
#   NG=2 SMOKE=1 bash benchmarks/gpu_paper.sh /tmp/gp_smoke
set -uo pipefail
R=${1:-/tmp/run}
. "$(dirname "$0")/gpu_lib.sh"  # FABRICS, NG, T1_ARGS, COLUMNS (and SMOKE versions)
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
note "start: $NG GPUs; columns $COLUMNS; table1 $T1_ARGS"
# 1. The training set and the evaluation set, each one process over every GPU.
step dataset 600 python -m experiments.generate_dataset --out="$R/ds" $DS_ARGS
step eval_set 600 python -m experiments.make_eval_set --out="$R/eval" $EVAL_ARGS
# 2. Table 1's simulation-split networks: one program, NG processes, each its share.
step table1 3000 "${LAUNCH[@]}" --command="python -m experiments.table1 \
  --dataset=$R/ds --workdir=$R/t1 $T1_ARGS --columns=$COLUMNS --splits=simulation"
if [ "$LATENCY" = 1 ]; then  # one estimate after compile
  gi=${FABRICS[1]}
  step latency 900 python -m benchmarks.estimate_latency \
    --recording="$R/eval/fabrics/$gi/0000" --material="$gi" $EST_ARGS \
    --model="$R/t1/physnet_depth/simulation/$gi" --out="$R/latency.json" \
    --settings=psd
fi
# 3. Tables 2 and 3: every recording x method, each process its share in lockstep.
step tables 3000 "${LAUNCH[@]}" --command="python -m experiments.tables \
  --eval=$R/eval --models=$R/t1 --workdir=$R/tables --methods=$COLUMNS $EST_ARGS"
# 4. The random-split runs of Table 1's k-NN column.
[ "$RANDOM_SPLIT" = 1 ] && step table1_all 3000 "${LAUNCH[@]}" --command="python -m \
  experiments.table1 --dataset=$R/ds --workdir=$R/t1 $T1_ARGS --columns=$COLUMNS"
note "all done"
