#!/usr/bin/env bash
# Can wind speed and area weight be told apart? One job, one or two GPUs:
#   1. experiments.separability: every fabric over a (wind, area weight) grid
#      with four gust seeds, motion statistics and their Cramer-Rao bounds
#      (no network);
#   2. per fabric in LANDSCAPE (default gray interlock and black denim): a
#      real-like recording (generate_dataset
#      --preset=eval), the paper's training set of that fabric, its
#      PhySNet-depth (validation-chosen epoch, as Table 1 trains it), and
#      experiments.landscape: the estimate's PSD along each parameter and over
#      the (wind, area weight) plane around the recording's truth.
# Each step is one process over every GPU (its worlds split over them).
# Usage: setsid bash benchmarks/gpu_identify.sh /tmp/id >/tmp/id.log 2>&1 &
# Progress: /tmp/id/status.txt; results: sep/, landscape_<fabric>/.
set -u
R=${1:-/tmp/id}
LANDSCAPE=${LANDSCAPE:-gray_interlock,black_denim}
. "$(dirname "$0")/gpu_lib.sh"  # note, step, T1_ARGS, NG
P=${SMOKE:+--preset=smoke}  # SMOKE=1: every step tiny, to check the script on a CPU
note "start: $NG x $(nvidia-smi --query-gpu=name --format=csv,noheader | head -1)"
lane() {  # fabric
  local m=$1
  step "eval_$m" 400 python -m experiments.generate_dataset --preset=eval \
    --out="$R/eval/$m" --materials="$m" --sequences=1 --batch_size=1 \
    ${SMOKE:+--resolution=32 --cloth_resolution=8 --frames=24} || return 1
  step "dataset_$m" 400 python -m experiments.generate_dataset --out="$R/ds_$m" \
    --materials="$m" $P ${SMOKE:+--sequences=12} || return 1
  step "train_$m" 600 python -m experiments.table1 --dataset="$R/ds_$m" \
    --workdir="$R/t1_$m" --columns=physnet_depth --splits=simulation --materials="$m" \
    $T1_ARGS --train_only || return 1
  step "landscape_$m" 900 python -m experiments.landscape \
    --recording="$R/eval/$m/$m/0000" --model="$R/t1_$m/physnet_depth/simulation/$m" \
    --workdir="$R/landscape_$m" --batch="${BATCH:-48}" $P
}
step separability 900 python -m experiments.separability --workdir="$R/sep" $P
IFS=, read -ra MS <<<"$LANDSCAPE"
for m in "${MS[@]}"; do
  lane "$m"
done
note done
