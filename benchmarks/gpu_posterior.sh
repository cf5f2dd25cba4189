#!/usr/bin/env bash
# One GPU's work for the posterior estimate, in stages (each fits one device call):
#   paper        a paper-size PhySNet-depth for gray interlock (its 30 training
#                simulations x 6 cameras x 60 frames at 256x256) and NREC
#                (default 3) real-like recordings (generate_dataset --preset=eval);
#   latency      then, on the same machine: benchmarks/estimate_latency.py (the
#                default posterior, and with PAPER=1 the paper's argmin, after
#                compile) and Tables 2-style estimates of the NREC recordings in
#                lockstep with the default posterior (and with PAPER=1 the argmin).
#   coverage     after paper: NREC real-like recordings for each seed of
#                EVAL_SEEDS (default 1000-1003; 1000 is the paper stage's set),
#                truths drawn over the search box, each set estimated by the
#                paper network in its own process, concurrently (video alone;
#                READING=wind_reading_sd or area_weight_reading_sd adds a 2% reading,
#                drawn with the set's seed: recording k of every set would
#                otherwise get the same draw). DISTANCE (e.g. shape, energy+shape)
#                and SHARPNESS set the estimate's --distance and --sharpness,
#                LIKELIHOOD (e.g. synthetic) its --likelihood.
# Usage: benchmarks/gpu_posterior.sh STAGE [RUN_DIR]; logs and results go to $OUT
# (default out/benchmarks/posterior, outside git; not benchmarks/results).
# SMOKE=1 shrinks everything to check the script on a CPU.
set -euo pipefail
stage=${1:?stage: paper, latency or coverage}
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
case "$stage" in
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
  *) echo "unknown stage $stage"; exit 2 ;;
esac
