#!/usr/bin/env bash
# The same program on 1 GPU and on every GPU of the machine (issue 21), in stages
# that each fit one device call; a stage's runs differ only in CUDA_VISIBLE_DEVICES:
#   sweep     the paper's dataset sweep (7 fabrics x 30 simulations x 6 cameras x
#             60 frames, one batch of 210 worlds), after a tiny run that fills
#             Warp's kernel cache;
#   setup     a quick PhySNet-depth for gray interlock (EPOCHS, default 1, on the
#             sweep's simulations) and NREC (default 21) real-like recordings;
#   lockstep  Tables 2-style estimates of the NREC recordings in lockstep
#             (experiments.tables), a fixed ITERS iterations after the initial
#             design so every run does the same work; G (default: every count
#             in GPUS) picks the runs.
#   calibrate the paper-size calibration study (experiments.calibrate
#             --preset=paper --pairs=PAIRS --simulate_only, PAIRS default 2:
#             14 x PAIRS recordings, every fabric): on 1 GPU, and on N GPUs as N
#             processes of one GPU each (experiments.launch; each estimates its
#             share of the recordings in its own lockstep), after a tiny run
#             that fills Warp's kernel cache; SHARDED=1 runs one process over
#             the N GPUs instead (its worlds split by jax.sharding; logs
#             calsharded_<N>gpu.log, read against calibrate_1gpu.log). Each run starts
#             with its own empty JAX cache ($R/jax_cache_<N>), so neither
#             loads what the other compiled, whatever the order: GPUS="2 1"
#             PAIRS=15 SHARDED=1 is issue 41's 210-recording comparison.
# Usage: OUT=/path bash benchmarks/gpu_scaling.sh STAGE [RUN_DIR] (OUT default
# out/gpu_scaling, scaling_report's default, outside git; not benchmarks/results); then
#   python -m benchmarks.scaling_report --logs=$OUT   (the table and JSON).
# GPUS lists the device counts (default "1 N", N = every GPU). SMOKE=1 checks the
# script on a CPU with tiny sizes (XLA's host devices stand in for GPUs).
set -uo pipefail
stage=${1:?stage: sweep, setup, lockstep or calibrate}
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
case "$stage" in
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
  *) echo "unknown stage $stage"; exit 2 ;;
esac
