#!/usr/bin/env bash
# Table 1 alone on every GPU of one machine: the training set (on GPU 0), then
# the per-fabric trainings of COLUMNS x SPLITS, pulled by the GPUs from one
# queue (longest tasks first), then the table and its similarity maps.
#   COLUMNS=physnet_depth,sdn_depth SPLITS=random \
#     setsid bash benchmarks/gpu_table1.sh /tmp/t1run >/tmp/t1run.log 2>&1 &
# Progress: $R/status.txt; results: $R/t1/table1.md and table1.json.
# On a CPU, NG=2 SMOKE=1 checks the script with tiny settings (MuJoCo C).
set -u
R=${1:-/tmp/t1run}
COLUMNS=${COLUMNS:-sdn_rgb,sdn_depth,physnet_rgb,physnet_depth}
SPLITS=${SPLITS:-random}
EPOCHS=${EPOCHS:-30}
VAL=${VAL:-0.2}
PATIENCE=${PATIENCE:-4}
export PYTHONPATH=${PYTHONPATH:-/tmp/site:$PWD} PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
NG=${NG:-$(nvidia-smi -L | wc -l)}
FABRICS=(white_tablecloth gray_interlock black_denim sparkle_fleece pink_nylon ponte_roma red_violet)
DS_ARGS="--batch_size=210"
T1_ARGS="--epochs=$EPOCHS --val_fraction=$VAL --patience=$PATIENCE"
if [ -n "${SMOKE:-}" ]; then
  FABRICS=(gray_interlock black_denim)
  DS_ARGS="--preset=smoke --sequences=10 --materials=gray_interlock,black_denim"
  T1_ARGS="--preset=smoke --epochs=3 --val_fraction=$VAL --patience=1 --test_fraction=0.2"
fi
[[ $COLUMNS == *rgb* ]] && DS_ARGS="$DS_ARGS --rgb"
mkdir -p "$R/logs" "$R/queue"
T0=$SECONDS
. "$(dirname "$0")/gpu_lib.sh"
T1="python -m experiments.table1 --dataset=$R/ds --workdir=$R/t1 $T1_ARGS --train_only"
note "start: $NG GPUs; columns $COLUMNS; splits $SPLITS; table1 $T1_ARGS"
for s in ${SPLITS//,/ }; do make_queue "$s"; done >"$R/queue/t1.txt"

lane() {
  local g=$1
  if [ "$g" -eq 0 ]; then
    step 0 dataset 900 python -m experiments.generate_dataset --out="$R/ds" $DS_ARGS \
      && touch "$R/ds.ok"
    touch "$R/ds.ended"
  fi
  wait_for "$R/ds.ended"
  [ -e "$R/ds.ok" ] && drain "$g" t1 1500
}
for ((g = 0; g < NG; g++)); do lane "$g" & done
wait
[ -e "$R/ds.ok" ] || { note "no dataset: stopped"; exit 1; }
step 0 table1 900 python -m experiments.table1 --dataset="$R/ds" --workdir="$R/t1" \
  $T1_ARGS --columns="$COLUMNS" --splits="$SPLITS"
note "all done"
