#!/usr/bin/env bash
# The paper-size pipeline on every GPU of one machine, as one background job:
# paper dataset (depth + RGB) and the real-like evaluation set, Table 1's
# networks (four columns x two splits x seven fabrics; one share per GPU),
# the learning-rate choice, Tables 2 and 3 for the four methods (lockstep
# estimates, one shard per GPU), the tables, and one recording's estimate time.
#   setsid bash benchmarks/gpu_paper.sh /tmp/run >/tmp/run.log 2>&1 &
# Progress: /tmp/run/status.txt. Every step resumes: rerun after an interruption.
set -uo pipefail
R=${1:-/tmp/run}
EPOCHS=${EPOCHS:-12}
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
mkdir -p "$R/logs"
NG=$(nvidia-smi -L | wc -l)
T0=$SECONDS
note() { echo "$((SECONDS - T0)) s: $*" >>"$R/status.txt"; }
step() {  # gpu name seconds command...
  local gpu=$1 name=$2 secs=$3
  shift 3
  local t=$SECONDS
  CUDA_VISIBLE_DEVICES=$((gpu % NG)) timeout "$secs" "$@" >"$R/logs/$name.log" 2>&1
  local rc=$?
  note "$name (gpu $((gpu % NG))): exit $rc in $((SECONDS - t)) s"
  return $rc
}
wait_for() { while [ ! -e "$1" ]; do sleep 5; done; }
T1="python -m experiments.table1 --dataset=$R/ds --workdir=$R/t1 --epochs=$EPOCHS --train_only"
note "start: $NG GPUs, $EPOCHS epochs"

lane() {  # gpu: its share of the work
  local g=$1  # (step runs on GPU g % NG)
  case $g in
    0) step $g dataset 600 python -m experiments.generate_dataset --out="$R/ds" --rgb \
         --batch_size=210 && touch "$R/ds.done"
       step $g t1_physnet_depth_sim 1500 $T1 --columns=physnet_depth --splits=simulation
       touch "$R/physnet_depth.done"
       step $g select_lr 900 python -m experiments.train --dataset="$R/ds" \
         --workdir="$R/lr" --materials=gray_interlock --epochs=$EPOCHS --select_lr=1e-2,1e-3 ;;
    1) step $g eval_set 600 python -m experiments.make_eval_set --out="$R/eval" --sequences=3 \
         && touch "$R/eval.done"
       wait_for "$R/ds.done"
       step $g t1_physnet_depth_random 1500 $T1 --columns=physnet_depth --splits=random
       step $g t1_sdn_depth_sim 900 $T1 --columns=sdn_depth --splits=simulation
       touch "$R/sdn_depth.done" ;;
    2) wait_for "$R/ds.done"
       step $g t1_physnet_rgb_sim 1500 $T1 --columns=physnet_rgb --splits=simulation
       touch "$R/physnet_rgb.done"
       step $g t1_sdn_rgb_sim 900 $T1 --columns=sdn_rgb --splits=simulation
       touch "$R/sdn_rgb.done" ;;
    3) wait_for "$R/ds.done"
       step $g t1_physnet_rgb_random 1500 $T1 --columns=physnet_rgb --splits=random
       step $g t1_sdn_random 900 $T1 --columns=sdn_depth,sdn_rgb --splits=random ;;
  esac
}

shard() {  # gpu: its chunk of Tables 2 and 3 (every simulation-split network)
  local g=$1
  for f in eval physnet_depth physnet_rgb sdn_depth sdn_rgb; do wait_for "$R/$f.done"; done
  step "$g" "tables_shard$g" 1500 python -m experiments.tables --eval="$R/eval" \
    --models="$R/t1" --workdir="$R/tables" --batched --shard="$g" --num_shards=4
}

if [ "$NG" -lt 4 ]; then  # fewer GPUs: the same steps one after another on GPU 0
  for g in 0 1 2 3; do lane "$g"; done
  for g in 0 1 2 3; do shard "$g"; done
else
  for g in 0 1 2 3; do (lane "$g"; shard "$g") & done
  wait
fi
step 0 table1 900 python -m experiments.table1 --dataset="$R/ds" --workdir="$R/t1" \
  --epochs=$EPOCHS &
step 1 tables 300 python -m experiments.tables --eval="$R/eval" --models="$R/t1" \
  --workdir="$R/tables" &
step 2 latency 900 python benchmarks/estimate_latency.py \
  --recording="$R/eval/fabrics/gray_interlock/0000" --material=gray_interlock \
  --model="$R/t1/physnet_depth/simulation/gray_interlock" --out="$R/latency.json" &
wait
note "all done"
touch "$R/all.done"
