#!/usr/bin/env bash
# The GPU jobs behind BENCHMARKS.md, one stage a call:
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
#   posterior SUB [RUN]   one GPU's work for the posterior estimate ($OUT default
#                  out/benchmarks/posterior), SUB one of:
#                  paper: a paper-size PhySNet-depth for gray interlock and NREC
#                    (default 3) real-like recordings;
#                  latency: then benchmarks/estimate_latency.py (after compile;
#                    PAPER=1 adds the paper's argmin) and Tables 2-style estimates of
#                    the NREC recordings in lockstep;
#                  coverage: after paper, NREC recordings for each seed of EVAL_SEEDS
#                    (default 1000-1003), each set estimated in its own process
#                    (READING=wind_reading_sd or area_weight_reading_sd: a 2% reading;
#                    DISTANCE, SHARPNESS, LIKELIHOOD: the estimate's flags).
#   scaling SUB [RUN]   the same program on 1 GPU and on every GPU, the runs
#                  differing only in CUDA_VISIBLE_DEVICES ($OUT default
#                  out/gpu_scaling, read by python -m benchmarks.scaling_report
#                  --logs=$OUT); GPUS lists the counts (default "1 N"), G picks them:
#                  sweep: the paper's dataset sweep (210 worlds), after a warm-up;
#                  setup: a quick PhySNet-depth (EPOCHS, default 1) and NREC
#                    (default 21) real-like recordings;
#                  lockstep: Tables 2-style estimates of them in lockstep, ITERS
#                    (default 2) iterations after the design;
#                  calibrate: the paper-size calibration (PAIRS, default 2: 14 x
#                    PAIRS recordings) on 1 GPU and as N processes of one GPU each
#                    (SHARDED=1: one process over the N), each run with its own
#                    empty JAX cache.
#   camera SUB [RUN]   issue 77's runs for estimates carrying the intake's
#                  alignment error, each camera error drawn per recording over
#                  CAM (default 3 cm / 2.5 deg, spread 1.25: 0.86-10.5 cm,
#                  0.72-8.7 deg); every SUB resumes, one call (TIME_LIMIT, default
#                  540 s) at a time; RUN default /tmp/camera; the strip's
#                  bending-length readings drawn as the depth reader's (STRIP,
#                  default 1.8%, spread 0.55: 0.46-7.1%). SUB one of:
#                  tables: the paper-size calibration (PAIRS, default 15), and
#                    once simulated its analysis installed; the table is kept in
#                    RUN (a fresh copy of the tree lacks it) and in $OUT, with
#                    the packed estimates (analyse them elsewhere);
#                    CAM=--camera_errors=FILES: cameras off as the measured
#                    intakes of benchmarks.alignment_error's FILES erred (with
#                    --physics=mismatched --centred_levels: the shipped ones);
#                  protocol: air_protocol's free-mode check with those errors
#                    (SETS, default 8, of seed SEED, default 7) into $OUT;
#                  intake: the windy rig's recordings of another physics (RECIPE,
#                    default mismatched; WINDS, default six; RIG=field=value,...:
#                    the rig changed, e.g. its camera, rig.with_fields;
#                    DRAWS=SEED: each its own fabric drawn over the prior, as
#                    the tables' are; RIG_PAIRS=N with DRAWS: N pairs drawn as
#                    the tables draw theirs, the seven fabrics in turn, their
#                    estimates' files tarred into $OUT for calibrate --rig_runs)
#                    taken in
#                    as a user's, with the tables of RUN, one estimate at a
#                    time (three at once overrun an H100).
# Training: at most EPOCHS (30) epochs, chosen on VAL (0.2) of the training
# simulations, stopping after PATIENCE (4) without a better one. COLUMNS: the
# methods (default all four). SMOKE=1 checks paper, table1, identify, engine,
# posterior and scaling on a CPU with tiny settings (NG=2: two launcher
# processes share it). Set PYTHONPATH yourself if the dependencies live outside
# the interpreter.
set -uo pipefail
stage=${1:?stage: paper, table1, collect, identify, one, fabrics_make, fabrics, engine, render, motion, posterior, scaling or camera}
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

posterior() (  # SUB [RUN]: the posterior's stages (a subshell: its settings stay in it)
  set -e
  sub=${1:?posterior stage: paper, latency or coverage}
  R=${2:-/tmp/posterior_run}
  OUT=${OUT:-out/benchmarks/posterior}
  mkdir -p "$R" "$OUT"
  export PYTHONUNBUFFERED=1
  GI=gray_interlock
  if [ -n "${SMOKE:-}" ]; then
    DS="--preset=smoke --materials=$GI --sequences=4"
    TR="--preset=smoke"
    EV="--preset=smoke --materials=$GI --sequences=2 --resolution=32 --frames=8 --cloth_resolution=8"
    EST="--preset=smoke --backend=c"
    LAT="--backend=c --settings=psd_smoke --repeats=1"
  else
    DS="--materials=$GI --batch_size=30"
    TR="--val_fraction=0.2 --patience=4"
    EV="--preset=eval --materials=$GI --sequences=${NREC:-3} --batch_size=${NREC:-3}"
    EST=""
    LAT="--backend=mjx --settings=psd${PAPER:+,paper} --repeats=1"
  fi
  case "$sub" in
    paper)
      python -m experiments.generate_dataset --out="$R/ds" $DS 2>&1 | tail -20 | tee "$OUT/dataset.log"
      python -m experiments.train --dataset="$R/ds" --workdir="$R/t1/physnet_depth/simulation" \
        --materials=$GI $TR 2>&1 | tail -5 | tee "$OUT/train.log"
      python -m experiments.generate_dataset --out="$R/eval/fabrics" $EV 2>&1 | tail -8 | tee "$OUT/eval.log"
      ;;
    latency)
      [ -z "${SMOKE:-}" ] && python -m benchmarks.estimate_latency --recording="$R/eval/fabrics/$GI/0000" --material=$GI \
        --model="$R/t1/physnet_depth/simulation/$GI" --out="$OUT/latency.json" $LAT 2>&1 \
        | tee "$OUT/latency.log"
      for p in ${PAPER:+paper} default; do
        pre=$p; [ -n "${SMOKE:-}" ] && pre=smoke
        python -m experiments.tables --eval="$R/eval" --models="$R/t1" --workdir="$R/tables_$p" \
          --methods=physnet_depth --preset=$pre ${EST:+--backend=c} 2>&1 | tail -30 | tee "$OUT/tables_$p.log"
        cp "$R/tables_$p/tables.json" "$OUT/tables_$p.json"
      done
      cp "$R"/tables_default/physnet_depth/fabrics/$GI-0000/posterior.png "$OUT/posterior_${GI}_0000.png"
      ;;
    coverage)
      pre=default; [ -n "${SMOKE:-}" ] && pre=smoke
      seeds=${EVAL_SEEDS:-1000 1001 1002 1003}
      for seed in $seeds; do
        python -m experiments.generate_dataset --out="$R/eval_$seed/fabrics" $EV --seed="$seed" 2>&1 \
          | tail -3 > "$OUT/eval_$seed.log"
      done
      read_flag=""; [ -n "${READING:-}" ] && read_flag="--$READING=0.02"
      name=${READING:-video}${DISTANCE:+_$DISTANCE}${LIKELIHOOD:+_$LIKELIHOOD}${SHARPNESS:+_c$SHARPNESS}
      pids=""
      for seed in $seeds; do
        XLA_PYTHON_CLIENT_MEM_FRACTION=0.2 \
        python -m experiments.tables --eval="$R/eval_$seed" --models="$R/t1" --workdir="$R/cov_${name}_$seed" \
          --methods=physnet_depth --preset=$pre ${EST:+--backend=c} $read_flag \
          ${READING:+--reading_seed=$seed} ${DISTANCE:+--distance=$DISTANCE} \
          ${SHARPNESS:+--sharpness=$SHARPNESS} ${LIKELIHOOD:+--likelihood=$LIKELIHOOD} \
          > "$OUT/cov_${name}_$seed.log" 2>&1 &
        pids="$pids $!"
      done
      for p in $pids; do wait "$p"; done
      for seed in $seeds; do
        tail -6 "$OUT/cov_${name}_$seed.log"
        cp "$R/cov_${name}_$seed/tables.json" "$OUT/cov_${name}_$seed.json"
      done
      ;;
    *) echo "unknown posterior stage $sub" >&2; exit 2 ;;
  esac
)

scaling() (  # SUB [RUN]: one program on 1 GPU and on every GPU
  sub=${1:?scaling stage: sweep, setup, lockstep or calibrate}
  R=${2:-/tmp/scaling_run}
  OUT=${OUT:-out/gpu_scaling}
  mkdir -p "$R" "$OUT"
  export PYTHONPATH=${PYTHONPATH:+$PYTHONPATH:}$PWD PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
  NG=$(nvidia-smi -L 2>/dev/null | wc -l)
  [ "$NG" -ge 1 ] 2>/dev/null || NG=2
  GPUS=${GPUS:-"1 $NG"}
  GI=gray_interlock
  NREC=${NREC:-21}
  ITERS=${ITERS:-2}
  DS="--batch_size=210"
  WARM="--materials=$GI --sequences=2 --batch_size=2 --frames=4"
  TRAIN="--epochs=${EPOCHS:-1} --val_fraction=0.2"
  EV="--preset=eval --materials=$GI --sequences=$NREC --batch_size=$NREC"
  TAB="--methods=physnet_depth --min_iter=$ITERS --max_iter=$ITERS"
  CAL="--preset=paper --pairs=${PAIRS:-2} --simulate_only"
  if [ -n "${SMOKE:-}" ]; then
    S="--preset=smoke --backend=c"
    DS="$S --materials=$GI,black_denim --sequences=4 --batch_size=8"
    WARM="$S --materials=$GI --sequences=1 --batch_size=1"
    TRAIN="--preset=smoke --epochs=1"
    EV="$S --materials=$GI --sequences=$NREC --batch_size=$NREC --resolution=32 --frames=8 --cloth_resolution=8"
    TAB="$TAB --preset=smoke --backend=c"
    CAL="--preset=smoke --distance=shape --materials=$GI --pairs=1 --backend=c --simulate_only"
  fi
  devices() {  # the first $1 devices, as CUDA_VISIBLE_DEVICES (or XLA host devices)
    export CUDA_VISIBLE_DEVICES
    CUDA_VISIBLE_DEVICES=$(seq -s, 0 $(($1 - 1)))
    [ -n "${SMOKE:-}" ] && export XLA_FLAGS="--xla_force_host_platform_device_count=$1"
  }
  timed() {  # name command...: its log in $OUT/name.log, then "wall S" appended
    local name=$1 t0
    shift
    t0=$EPOCHREALTIME
    "$@" >"$OUT/$name.log" 2>&1
    local rc=$?
    awk -v a="$t0" -v b="$EPOCHREALTIME" -v rc=$rc \
      'BEGIN { printf "wall %.2f s, exit %d\n", b - a, rc }' >>"$OUT/$name.log"
    echo "$name: $(tail -1 "$OUT/$name.log")"
  }
  case "$sub" in
    sweep)
      devices 1
      timed sweep_warmup python -m experiments.generate_dataset --out="$R/warm" $WARM
      for g in $GPUS; do
        devices "$g"
        rm -rf "$R/sweep_$g"
        timed "sweep_${g}gpu" python -m experiments.generate_dataset --out="$R/sweep_$g" $DS
        cp "$R/sweep_$g/summary.json" "$OUT/sweep_${g}gpu.json"
      done
      ;;
    setup)
      devices 1
      timed setup_train python -m experiments.train --dataset="$R/sweep_1" \
        --workdir="$R/t1/physnet_depth/simulation" --materials=$GI $TRAIN
      timed setup_eval python -m experiments.generate_dataset --out="$R/eval/fabrics" $EV
      ;;
    lockstep)
      for g in ${G:-$GPUS}; do
        devices "$g"
        rm -rf "$R/tables_$g"
        timed "lockstep_${g}gpu" python -m experiments.tables --eval="$R/eval" \
          --models="$R/t1" --workdir="$R/tables_$g" $TAB
      done
      ;;
    calibrate)
      devices 1
      timed calibrate_warmup python -m experiments.generate_dataset --out="$R/warm" $WARM
      for g in ${G:-$GPUS}; do
        rm -rf "$R/cal_$g" "$R/jax_cache_$g"
        export PHYSNET_JAX_CACHE=$R/jax_cache_$g
        if [ "$g" = 1 ]; then
          devices 1
          timed calibrate_1gpu python -m experiments.calibrate $CAL --workdir="$R/cal_1"
        elif [ -n "${SHARDED:-}" ]; then
          devices "$g"
          timed "calsharded_${g}gpu" python -m experiments.calibrate $CAL --workdir="$R/cal_$g"
        else
          devices "$g"
          gpp=1  # each process its own GPU (on a CPU: one host device each)
          [ -n "${SMOKE:-}" ] && gpp=0 && export XLA_FLAGS=--xla_force_host_platform_device_count=1
          timed "calibrate_${g}gpu" python -m experiments.launch --processes="$g" \
            --gpus_per_process=$gpp --port=$((12355 + g)) \
            --command="python -m experiments.calibrate $CAL --workdir=$R/cal_$g"
        fi
      done
      ;;
    *) echo "unknown scaling stage $sub" >&2; exit 2 ;;
  esac
)

camera() (  # SUB [RUN]: see the header
  local sub=${1:?camera: tables, protocol or intake}
  R=${2:-/tmp/camera}
  OUT=${OUT:-out/benchmarks/camera}
  mkdir -p "$R/logs" "$OUT"
  local limit=${TIME_LIMIT:-540}
  local cam=${CAM:---camera_sd_m=0.03 --camera_sd_deg=2.5 --camera_sd_spread=1.25}
  local strip=${STRIP:---length_sd=0.018 --length_sd_spread=0.55}
  local cal="--preset=paper --pairs=${PAIRS:-15} $cam $strip --workdir=$R/cal"
  case "$sub" in
    tables)
      if [ ! -f "$R/cal/simulated" ]; then
        step cal_simulate "$((limit + 60))" python -m experiments.calibrate $cal \
          --simulate_only --time_limit="$limit" && touch "$R/cal/simulated"
        tail -3 "$R/logs/cal_simulate.log"
        return 0  # exit 75: not done; either way, call again
      fi
      step cal_install 900 python -m experiments.calibrate $cal --analyse_only --install
      cp experiments/pipeline/calibration_shape_paper_camera_*-*.json "$R/" &&
        cp "$R"/calibration_shape_paper_camera_*.json "$R/cal/calibration.md" "$OUT/" &&
        cp -r "$R/cal/packed" "$OUT/"
      tail -30 "$R/logs/cal_install.log"
      ;;
    protocol)
      step protocol "$((limit + 60))" python -m experiments.air_protocol --modes=free \
        --sets="${SETS:-8}" --seed="${SEED:-7}" $cam $strip --length_dof=10 \
        --workdir="$R/protocol_${SEED:-7}" \
        --out="$OUT/protocol_${SEED:-7}.json" --time_limit="$limit"
      tail -8 "$R/logs/protocol.log"
      ;;
    intake)
      cp "$R"/calibration_shape_paper_camera_*.json experiments/pipeline/
      # the rig's own process must not take the GPU its estimates' processes need
      XLA_PYTHON_CLIENT_PREALLOCATE=false step intake "$((limit + 60))" python -m benchmarks.windy_rig --preset=gpu \
        --recipe="${RECIPE:-mismatched}" --parallel=1 --recipe_fields=seed="${SEED:-51}"${RIG:+,$RIG} \
        --winds="${WINDS:-2.5,2.9,3.3,3.7,4.1,4.5}" --workdir="$R/intake_${SEED:-51}" \
        ${DRAWS:+--fabric_draws=$DRAWS} ${RIG_PAIRS:+--pairs=$RIG_PAIRS --materials=$(IFS=,; echo "${FABRICS[*]}")}
      cp "$R/intake_${SEED:-51}/windy_rig.json" "$OUT/intake_${SEED:-51}.json"
      # what a table fitted on these recordings reads (calibrate --rig_runs)
      (cd "$R" && find "intake_${SEED:-51}" -path '*recording/*.json' -o -name estimate.json \
        -o -name posterior.npz | tar -cf - -T - | split -b 15m - "$OUT/rig_${SEED:-51}.tar.")
      tail -14 "$R/logs/intake.log"
      ;;
    *) echo "unknown camera stage $sub" >&2; exit 2 ;;
  esac
)

case "$stage" in
  paper | table1 | identify | one | fabrics_make | fabrics | collect)
    run_folder "${1:-}"
    shift $(($# > 0 ? 1 : 0))
    "$stage" "$@"
    ;;
  posterior | scaling | camera)
    "$stage" "$@"
    ;;
  engine | render | motion)
    OUT=${OUT:-out/benchmarks/$stage}
    mkdir -p "$OUT"
    "$stage"
    ;;
  *) echo "unknown stage $stage" >&2; exit 2 ;;
esac
