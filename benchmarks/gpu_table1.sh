#!/usr/bin/env bash
# Table 1 alone on every GPU of one machine: the training set (on GPU 0), then
# the per-fabric trainings of COLUMNS x SPLITS, pulled by the GPUs from one
# queue (longest tasks first), then the table and its similarity maps.
#   COLUMNS=physnet_depth,sdn_depth SPLITS=random \
#     setsid bash benchmarks/gpu_table1.sh /tmp/t1run >/tmp/t1run.log 2>&1 &
# Progress: $R/status.txt; results: $R/t1/table1.md and table1.json.
# QUEUE=file: train only the task lines of that file ("name column split
# fabrics", as make_queue writes them; e.g. to finish the runs a budget cut)
# and end with `table1 --report_only` over what was trained.
# On a CPU, NG=2 SMOKE=1 checks the script with tiny settings (MuJoCo C).
set -u
R=${1:-/tmp/t1run}
. "$(dirname "$0")/gpu_lib.sh"  # FABRICS, NG, T1_ARGS, COLUMNS (and SMOKE versions)
SPLITS=${SPLITS:-random}
DS_ARGS="--batch_size=210"
[ -n "${SMOKE:-}" ] && DS_ARGS="--preset=smoke --sequences=10 --materials=gray_interlock,black_denim"
[[ $COLUMNS == *rgb* ]] && DS_ARGS="$DS_ARGS --rgb"
T1="python -m experiments.table1 --dataset=$R/ds --workdir=$R/t1 $T1_ARGS --train_only"
note "start: $NG GPUs; columns $COLUMNS; splits $SPLITS; table1 $T1_ARGS"
if [ -n "${QUEUE:-}" ]; then
  cp "$QUEUE" "$R/queue/t1.txt"
else
  for s in ${SPLITS//,/ }; do make_queue "$s"; done >"$R/queue/t1.txt"
fi

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
  $T1_ARGS --columns="$COLUMNS" --splits="$SPLITS" ${QUEUE:+--report_only}
note "all done"
