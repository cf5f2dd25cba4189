#!/usr/bin/env bash
# The GPU jobs behind BENCHMARKS.md, one stage a call (gpu_posterior.sh and
# gpu_scaling.sh hold the posterior's and the scaling runs' stages):
#   bash benchmarks/gpu.sh STAGE [RUN] [ARGS]
# Stages on a run folder RUN (progress in RUN/status.txt, logs in RUN/logs/;
# every step resumes: rerun after an interruption; long ones as a background
# job: setsid bash benchmarks/gpu.sh paper /tmp/run >/tmp/run.log 2>&1 &):
#   paper RUN      the paper-size pipeline on every GPU: the paper dataset and
#                  the real-like evaluation set (each one process over every
#                  GPU); Table 1's simulation-split networks (COLUMNS x seven
#                  fabrics) as one program of NG processes (experiments.launch);
#                  one estimate timed after compile (LATENCY=0: not); Tables 2
#                  and 3 for COLUMNS; the random-split runs of Table 1's k-NN
#                  column (RANDOM_SPLIT=0: not). NOISE=1: the training frames go
#                  through the sensor model.
#   table1 RUN     Table 1 alone: the training set, then COLUMNS x SPLITS
#                  (default random) as one program of NG processes.
#   collect RUN DEST   the small outputs of a paper or table1 run (status, the
#                  tables, each evaluation set's summary, Table 1, the trainings'
#                  metrics.jsonl) into DEST, the tables of what has finished.
#   identify RUN   experiments.separability (every fabric, the motion's
#                  Cramer-Rao bound, no network), then per fabric in LANDSCAPE
#                  (default gray interlock, black denim) a real-like recording,
#                  its PhySNet-depth and experiments.landscape around its truth.
#   one RUN [RECORDING]   one GPU: a gray interlock training set and its
#                  PhySNet-depth, training throughput (float32) and the estimate
#                  after compile for SETTINGS (default default,gp_on_gpu,q16).
#   fabrics_make RUN, fabrics RUN [FABRIC ...]   one recording of each fabric
#                  of another physics, then `python -m experiments.estimate`
#                  given only the recording, its fabric and a workdir, one
#                  process each, timed from the shell (RUN/times.txt); read with
#                  python -m benchmarks.default_fabrics --root=RUN.
# Stages writing logs and JSON to $OUT (default out/benchmarks/STAGE):
#   engine         the rollouts ('warp', 'mjx') beside MuJoCo Warp called
#                  directly at 210 and 1024 worlds (forces ablated, an event
#                  trace, the paper dataset's 210 x (1+3) s in one call), CG
#                  tolerances 1e-6 and 1e-5, and rendering 210 worlds.
#   render         the ray-caster against MuJoCo Warp's batch renderer, and
#                  training throughput in float32 and bfloat16.
#   motion         experiments.fabric_motion (does it move like fabric) and the
#                  paper dataset's summary and montages.
# Training: at most EPOCHS (30) epochs, chosen on VAL (0.2) of the training
# simulations, stopping after PATIENCE (4) without a better one. COLUMNS: the
# methods (default all four). SMOKE=1 checks paper, table1, identify and engine
# on a CPU with tiny settings (NG=2: two launcher processes share it). Set
# PYTHONPATH yourself if the dependencies live outside the interpreter.
set -uo pipefail
stage=${1:?stage: paper, table1, collect, identify, one, fabrics_make, fabrics, engine, render or motion}
shift
export PYTHONPATH=${PYTHONPATH:+$PYTHONPATH:}$PWD PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
EPOCHS=${EPOCHS:-30} VAL=${VAL:-0.2} PATIENCE=${PATIENCE:-4}
NG=${NG:-$(nvidia-smi -L 2>/dev/null | wc -l)}
[ "$NG" -ge 1 ] 2>/dev/null || NG=1
FABRICS=(white_tablecloth gray_interlock black_denim sparkle_fleece pink_nylon ponte_roma red_violet)
GI=gray_interlock
T1_ARGS="--epochs=$EPOCHS --val_fraction=$VAL --patience=$PATIENCE"
COLUMNS=${COLUMNS:-sdn_rgb,sdn_depth,physnet_rgb,physnet_depth}
GPP=1
if [ -n "${SMOKE:-}" ]; then  # tiny settings for checking a stage on a CPU
  FABRICS=(gray_interlock black_denim)
  T1_ARGS="--preset=smoke --epochs=3 --val_fraction=$VAL --patience=1 --test_fraction=0.2"
  GPP=0
fi
# One program over every GPU: NG processes joined by jax.distributed, one GPU each.
LAUNCH=(python -m experiments.launch --processes="$NG" --gpus_per_process="$GPP")
T0=$SECONDS
note() { echo "$((SECONDS - T0)) s: $*" >>"$R/status.txt"; }
step() {  # name seconds command...: a run folder's step, logged under $R/logs
  local name=$1 secs=$2 t=$SECONDS
  shift 2
  timeout "$secs" "$@" >"$R/logs/$name.log" 2>&1
  local rc=$?
  note "$name: exit $rc in $((SECONDS - t)) s"
  return $rc
}
ostep() {  # name seconds command...: a step logged under $OUT
  local name=$1 secs=$2 t=$SECONDS
  shift 2
  timeout "$secs" "$@" >"$OUT/$name.log" 2>&1
  echo "$name: exit $? in $((SECONDS - t)) s"
}
gpu_name() { nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1; }
run_folder() {  # RUN (default /tmp/STAGE)
  R=${1:-/tmp/$stage}
  mkdir -p "$R/logs"
}

paper() {
  local ds="--batch_size=210" ev="--sequences=3" est="--preset=paper"
  if [ -n "${SMOKE:-}" ]; then
    ds="--preset=smoke --sequences=10 --materials=gray_interlock,black_denim"
    ev="--preset=smoke" est="--preset=smoke --backend=c"
  fi
  [[ $COLUMNS == *rgb* ]] && ds="$ds --rgb"
  [ "${NOISE:-0}" = 1 ] && ds="$ds --noise"
  note "start: $NG GPUs; columns $COLUMNS; table1 $T1_ARGS"
  step dataset 600 python -m experiments.generate_dataset --out="$R/ds" $ds
  step eval_set 600 python -m experiments.make_eval_set --out="$R/eval" $ev
  step table1 3000 "${LAUNCH[@]}" --command="python -m experiments.table1 \
    --dataset=$R/ds --workdir=$R/t1 $T1_ARGS --columns=$COLUMNS --splits=simulation"
  if [ "${LATENCY:-1}" = 1 ]; then
    local gi=${FABRICS[1]}
    step latency 900 python -m benchmarks.estimate_latency \
      --recording="$R/eval/fabrics/$gi/0000" --material="$gi" $est \
      --model="$R/t1/physnet_depth/simulation/$gi" --out="$R/latency.json" --settings=psd
  fi
  step tables 3000 "${LAUNCH[@]}" --command="python -m experiments.tables \
    --eval=$R/eval --models=$R/t1 --workdir=$R/tables --methods=$COLUMNS $est"
  [ "${RANDOM_SPLIT:-1}" = 1 ] && step table1_all 3000 "${LAUNCH[@]}" --command="python -m \
    experiments.table1 --dataset=$R/ds --workdir=$R/t1 $T1_ARGS --columns=$COLUMNS"
  note "all done"
}

table1() {
  local splits=${SPLITS:-random} ds="--batch_size=210"
  [ -n "${SMOKE:-}" ] && ds="--preset=smoke --sequences=10 --materials=gray_interlock,black_denim"
  [[ $COLUMNS == *rgb* ]] && ds="$ds --rgb"
  note "start: $NG GPUs; columns $COLUMNS; splits $splits; table1 $T1_ARGS"
  step dataset 900 python -m experiments.generate_dataset --out="$R/ds" $ds \
    || { note "no dataset: stopped"; return 1; }
  step table1 3000 "${LAUNCH[@]}" --command="python -m experiments.table1 \
    --dataset=$R/ds --workdir=$R/t1 $T1_ARGS --columns=$COLUMNS --splits=$splits"
  note "all done"
}

collect() {  # DEST
  local d=${1:?destination} f s
  mkdir -p "$d/metrics"
  cp "$R/status.txt" "$d/" 2>/dev/null
  if [ -d "$R/tables" ] && [ -d "$R/eval" ]; then
    timeout 300 python -m experiments.tables --eval="$R/eval" --models="$R/t1" \
      --workdir="$R/tables" --methods="$COLUMNS" --report_only >"$d/tables_report.log" 2>&1
    cp "$R"/tables/tables.{md,json} "$R"/tables/*.png "$d/" 2>/dev/null
  fi
  for f in "$R"/eval/*/summary.json; do
    [ -e "$f" ] && s=${f%/summary.json} && cp "$f" "$d/eval_${s##*/}_summary.json"
  done
  if [ -d "$R/t1" ]; then
    timeout 600 python -m experiments.table1 --dataset="$R/ds" --workdir="$R/t1" \
      $T1_ARGS --columns="$COLUMNS" --splits=simulation,random --report_only \
      >"$d/table1_report.log" 2>&1
    cp "$R"/t1/table1.{md,json} "$d/" 2>/dev/null
    for f in "$R"/t1/*/*/*/metrics.jsonl; do
      [ -e "$f" ] || continue
      IFS=/ read -ra s <<<"${f#"$R"/t1/}"
      cp "$f" "$d/metrics/${s[0]}_${s[1]}_${s[2]}.jsonl"
    done
  fi
  for f in "$R"/logs/tables_shard*.log; do
    [ -e "$f" ] && { echo "== $f"; tail -n 20 "$f"; }
  done >"$d/tables_steps.txt"
  ls -R "$d" | head -50
}

identify() {
  local p=${SMOKE:+--preset=smoke} m
  note "start: $NG x $(gpu_name)"
  step separability 900 python -m experiments.separability --workdir="$R/sep" $p
  IFS=, read -ra ms <<<"${LANDSCAPE:-gray_interlock,black_denim}"
  for m in "${ms[@]}"; do
    step "eval_$m" 400 python -m experiments.generate_dataset --preset=eval \
      --out="$R/eval/$m" --materials="$m" --sequences=1 --batch_size=1 \
      ${SMOKE:+--resolution=32 --cloth_resolution=8 --frames=24} || continue
    step "dataset_$m" 400 python -m experiments.generate_dataset --out="$R/ds_$m" \
      --materials="$m" $p ${SMOKE:+--sequences=12} || continue
    step "train_$m" 600 python -m experiments.table1 --dataset="$R/ds_$m" \
      --workdir="$R/t1_$m" --columns=physnet_depth --splits=simulation --materials="$m" \
      $T1_ARGS --train_only || continue
    step "landscape_$m" 900 python -m experiments.landscape \
      --recording="$R/eval/$m/$m/0000" --model="$R/t1_$m/physnet_depth/simulation/$m" \
      --workdir="$R/landscape_$m" --batch="${BATCH:-48}" $p
  done
  note done
}

one() {  # [RECORDING]
  local rec=${1:-$R/eval/fabrics/$GI/0000}
  note "start: $(gpu_name)"
  if [ ! -e "$rec" ]; then
    step eval_set 300 python -m experiments.generate_dataset --preset=eval \
      --out="$R/eval/fabrics" --materials=$GI --sequences=1 --batch_size=1 || return 1
  fi
  step dataset 400 python -m experiments.generate_dataset --out="$R/ds" --materials=$GI || return 1
  step train 600 python -m experiments.table1 --dataset="$R/ds" --workdir="$R/t1" \
    --columns=physnet_depth --splits=simulation --materials=$GI $T1_ARGS --train_only || return 1
  step train_fp32 300 python -m benchmarks.train_throughput --precision=float32 \
    --out="$R/train_fp32.json"
  step latency 1200 python -m benchmarks.estimate_latency --recording="$rec" \
    --material=$GI --model="$R/t1/physnet_depth/simulation/$GI" \
    --settings="${SETTINGS:-default,gp_on_gpu,q16}" --repeats="${REPEATS:-2}" \
    --out="$R/latency.json"
  note done
}

fabrics_make() {
  python -m experiments.generate_dataset --preset=eval --sequences=1 \
    --physics=mismatched --out="$R/recordings" 2>&1 | tail -3
}

fabrics() {  # [FABRIC ...] (default: all 7)
  local f t rc list=("$@")
  [ ${#list[@]} -eq 0 ] && list=("${FABRICS[@]}")
  for f in "${list[@]}"; do
    t=$(date +%s%N)
    python -m experiments.estimate --recording="$R/recordings/$f/0000" \
      --material="$f" --workdir="$R/est_$f" >"$R/$f.log" 2>&1
    rc=$?
    echo "$f rc=$rc $((($(date +%s%N) - t) / 1000000)) ms" | tee -a "$R/times.txt"
  done
}

engine() {
  local p="benchmarks/physsim_throughput.py --c_baseline=false" b1=210 b2=1024 r=256 rb=210
  local pd=--paper_dataset tol
  if [ -n "${SMOKE:-}" ]; then
    p="$p --resolution=8 --seconds=0.05 --repeats=1" b1=2 b2=4 r=32 rb=3 pd=
  fi
  ostep direct 400 python $p --batch_sizes=$b1,$b2 --direct --backends=warp,mjx \
    --ablate_forces --event_trace $pd --out="$OUT/physsim_direct.json"
  for tol in 1e-6 1e-5; do
    ostep "tolerance_$tol" 90 python $p --batch_sizes=$b2 --backends=warp \
      --tolerance=$tol --out="$OUT/physsim_tolerance_$tol.json"
  done
  ostep render 120 python -m benchmarks.render_throughput --batch_sizes=$rb \
    --methods=raster --mujoco_frames=0 --repeats=1 --resolution=$r \
    ${SMOKE:+--frames=4 --cameras=2} --out="$OUT/render_210.json"
  grep -h "^|" "$OUT"/*.log
}

render() {  # MuJoCo's own renderer is timed on the CPU only (no EGL on the device)
  nvidia-smi -L >"$OUT/gpu.txt" 2>&1
  ostep render_raster 200 python -m benchmarks.render_throughput \
    --batch_sizes=1,16,64,210 --methods=raster --mjwarp --mujoco_frames=0 \
    --out="$OUT/render_gpu.json"
  ostep render_brute 60 python -m benchmarks.render_throughput --batch_sizes=1 \
    --methods=brute --mujoco_frames=0 --out="$OUT/render_brute_gpu.json"
  ostep train_fp32 150 python -m benchmarks.train_throughput --precision=float32 \
    --out="$OUT/train_gpu.json"
  ostep train_bf16 100 python -m benchmarks.train_throughput --precision=bfloat16 \
    --out="$OUT/train_gpu_bf16.json"
  tail -n 3 "$OUT"/*.log
}

motion() {
  ostep motion 330 python -m experiments.fabric_motion --workdir="$OUT/motion" --backend=mjx
  ostep dataset 250 python -m experiments.generate_dataset --out=/tmp/ds --batch_size=210
  cp /tmp/ds/summary.json "$OUT/dataset_summary.json" 2>/dev/null
  cp /tmp/ds/montage_*.png "$OUT/" 2>/dev/null
  tail -n 3 "$OUT"/*.log
}

case "$stage" in
  paper | table1 | identify | one | fabrics_make | fabrics | collect)
    run_folder "${1:-}"
    shift $(($# > 0 ? 1 : 0))
    "$stage" "$@"
    ;;
  engine | render | motion)
    OUT=${OUT:-out/benchmarks/$stage}
    mkdir -p "$OUT"
    "$stage"
    ;;
  *) echo "unknown stage $stage" >&2; exit 2 ;;
esac
