#!/usr/bin/env bash
# The single-GPU measurements the issues name, in one job on one GPU (the
# issues ask for an H100), each step alone on the GPU while it is timed:
#   1. a gray interlock training set (the paper preset, that fabric only) and
#      its PhySNet-depth (as Table 1 trains it: validation-chosen epoch);
#   2. training throughput, JAX against PyTorch eager and torch.compile
#      (benchmarks/train_throughput.py, float32, batch 32);
#   3. one recording's estimate after compile (benchmarks/estimate_latency.py)
#      for SETTINGS, the first of them the baseline of the ratio column.
# Usage (RECORDING: a real-like recording, e.g. from make_eval_set or
# `generate_dataset --preset=eval`; made here when absent):
#   setsid bash benchmarks/gpu_one.sh /tmp/one [RECORDING] >/tmp/one.log 2>&1 &
# Progress: /tmp/one/status.txt; results: train_fp32.json, latency.json.
set -u
R=${1:-/tmp/one}
REC=${2:-$R/eval/fabrics/gray_interlock/0000}
GI=gray_interlock
SETTINGS=${SETTINGS:-default,gp_on_gpu,q16}
export PYTHONPATH=${PYTHONPATH:+$PYTHONPATH:}$PWD PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
mkdir -p "$R/logs"
T0=$SECONDS
note() { echo "$((SECONDS - T0)) s: $*" >>"$R/status.txt"; }
step() {  # name seconds command...
  local name=$1 secs=$2 t=$SECONDS
  shift 2
  timeout "$secs" "$@" >"$R/logs/$name.log" 2>&1
  local rc=$?
  note "$name: exit $rc in $((SECONDS - t)) s"
  return $rc
}
note "start: $(nvidia-smi --query-gpu=name --format=csv,noheader | head -1)"
if [ ! -e "$REC" ]; then
  step eval_set 300 python -m experiments.generate_dataset --preset=eval \
    --out="$R/eval/fabrics" --materials=$GI --sequences=1 --batch_size=1 || exit 1
fi
step dataset 400 python -m experiments.generate_dataset --out="$R/ds" --materials=$GI || exit 1
step train 600 python -m experiments.table1 --dataset="$R/ds" --workdir="$R/t1" \
  --columns=physnet_depth --splits=simulation --materials=$GI --epochs=30 \
  --val_fraction=0.2 --patience=4 --train_only || exit 1
step train_fp32 300 python -m benchmarks.train_throughput --precision=float32 \
  --out="$R/train_fp32.json"
step latency 1200 python -m benchmarks.estimate_latency --recording="$REC" \
  --material=$GI --model="$R/t1/physnet_depth/simulation/$GI" \
  --settings="$SETTINGS" --repeats="${REPEATS:-2}" --out="$R/latency.json"
note done
