#!/usr/bin/env bash
# Gathers the small outputs of a gpu_paper.sh / gpu_table1.sh run into one
# folder (the device's $OUT), writing the tables of whatever has finished:
#   COLUMNS=physnet_depth,sdn_depth bash benchmarks/gpu_collect.sh /tmp/run "$OUT/run"
# Copies status.txt, the tables (markdown, JSON, bending-surface and PSD-candidate PNGs),
# each evaluation set's summary.json, Table 1, every
# training run's metrics.jsonl (as <column>_<split>_<fabric>.jsonl) and the last
# lines of each estimate shard's log. Checkpoints and datasets stay behind.
set -u
R=${1:?run folder}
D=${2:?destination}
. "$(dirname "$0")/gpu_lib.sh"  # T1_ARGS (the run's training settings), COLUMNS, PYTHONPATH
mkdir -p "$D/metrics"
cp "$R/status.txt" "$D/" 2>/dev/null
if [ -d "$R/tables" ] && [ -d "$R/eval" ]; then  # tables of the finished estimates
  timeout 300 python -m experiments.tables --eval="$R/eval" --models="$R/t1" \
    --workdir="$R/tables" --methods="$COLUMNS" --report_only >"$D/tables_report.log" 2>&1
  cp "$R"/tables/tables.{md,json} "$R"/tables/*.png "$D/" 2>/dev/null
fi
for f in "$R"/eval/*/summary.json; do  # each evaluation set's framing (coverage, re-draws)
  [ -e "$f" ] && s=${f%/summary.json} && cp "$f" "$D/eval_${s##*/}_summary.json"
done
if [ -d "$R/t1" ]; then
  timeout 600 python -m experiments.table1 --dataset="$R/ds" --workdir="$R/t1" \
    $T1_ARGS --columns="$COLUMNS" --splits=simulation,random --report_only >"$D/table1_report.log" 2>&1
  cp "$R"/t1/table1.{md,json} "$D/" 2>/dev/null
  for f in "$R"/t1/*/*/*/metrics.jsonl; do
    [ -e "$f" ] || continue
    IFS=/ read -ra p <<<"${f#"$R"/t1/}"
    cp "$f" "$D/metrics/${p[0]}_${p[1]}_${p[2]}.jsonl"
  done
fi
for f in "$R"/logs/tables_shard*.log; do
  [ -e "$f" ] && { echo "== $f"; tail -n 20 "$f"; }
done >"$D/tables_steps.txt"
ls -R "$D" | head -50
