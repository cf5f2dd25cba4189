#!/usr/bin/env bash
# Table 1 alone on every GPU of one machine: the training set, then the
# per-fabric trainings of COLUMNS x SPLITS as one program in NG processes
# joined by jax.distributed (experiments.launch; each trains its share), whose
# process 0 writes the table and its similarity maps once all have finished.
#   COLUMNS=physnet_depth,sdn_depth SPLITS=random \
#     setsid bash benchmarks/gpu_table1.sh /tmp/t1run >/tmp/t1run.log 2>&1 &
# Progress: $R/status.txt; results: $R/t1/table1.md and table1.json.
# On a CPU, NG=2 SMOKE=1 checks the script with tiny settings (MuJoCo C).
set -u
R=${1:-/tmp/t1run}
. "$(dirname "$0")/gpu_lib.sh"  # NG, T1_ARGS, COLUMNS (and SMOKE versions), step, note
SPLITS=${SPLITS:-random}
DS_ARGS="--batch_size=210"
[ -n "${SMOKE:-}" ] && DS_ARGS="--preset=smoke --sequences=10 --materials=gray_interlock,black_denim"
[[ $COLUMNS == *rgb* ]] && DS_ARGS="$DS_ARGS --rgb"
note "start: $NG GPUs; columns $COLUMNS; splits $SPLITS; table1 $T1_ARGS"
step dataset 900 python -m experiments.generate_dataset --out="$R/ds" $DS_ARGS \
  || { note "no dataset: stopped"; exit 1; }
step table1 3000 "${LAUNCH[@]}" --command="python -m experiments.table1 \
  --dataset=$R/ds --workdir=$R/t1 $T1_ARGS --columns=$COLUMNS --splits=$SPLITS"
note "all done"
