#!/usr/bin/env bash
# One GPU's work for the posterior estimate, in stages (each fits one device call):
#   calibration  experiments.calibrate at the demo's size: 100 pairs of held-out
#                simulated recordings (the evaluation recipe), coverage and ranks.
#   paper        a paper-size PhySNet-depth for gray interlock (its 30 training
#                simulations x 6 cameras x 60 frames at 256x256) and NREC
#                (default 3) real-like recordings (generate_dataset --preset=eval);
#   latency      then, on the same machine: benchmarks/estimate_latency.py (the
#                default posterior, and with PAPER=1 the paper's argmin, after
#                compile) and Tables 2-style estimates of the NREC recordings in
#                lockstep with the default posterior (and with PAPER=1 the argmin).
#   measured     after latency: the NREC recordings again, each with a simulated
#                anemometer reading (2%) as its prior, then with a simulated
#                scale-and-ruler reading (2%) (experiments.tables
#                --wind_reading_sd / --area_weight_reading_sd: the search spends
#                its simulations on the reading's slice), and
#                benchmarks/measured_modes.py on the default run's GPs (the same
#                readings applied after a video-alone search), side by side.
#   members      after paper: MEMBERS (default 2) more networks of the same
#                recipe on the same simulations, seeds 1..MEMBERS ($R/t1_s<seed>).
#   ensemble     after members: the NREC recordings with the ensemble of the
#                paper network and its MEMBERS (experiments.tables --models=a,b,c),
#                video alone and with the 2% anemometer; then every member alone
#                with the anemometer (side by side, concurrently).
#   coverage     after paper: NREC real-like recordings for each seed of
#                EVAL_SEEDS (default 1000-1003; 1000 is the paper stage's set),
#                truths drawn over the search box, each set estimated by the
#                paper network in its own process, concurrently (video alone;
#                READING=wind_reading_sd or area_weight_reading_sd adds a 2% reading,
#                drawn with the set's seed: recording k of every set would
#                otherwise get the same draw). DISTANCE (e.g. shape, energy+shape)
#                and SHARPNESS set the estimate's --distance and --sharpness,
#                LIKELIHOOD (e.g. synthetic) its --likelihood.
#   joint        after paper (DISTANCE=shape: needs no network, so no paper stage): benchmarks/joint_pairs.py, NGROUPS (default 8) groups of
#                GROUP (default 3) real-like recordings sharing bending and area
#                weight, a 2% anemometer reading at each, every search in lockstep,
#                then each group's joint posterior (DISTANCE, LIKELIHOOD and
#                SHARPNESS as for coverage; GUSTS the simulations' gust intensity;
#                SECONDS_CLIP: each recording's length, s, the estimate's too;
#                CLOTH: the simulations' cloth vertices per side, 33 as the recordings').
# Usage: benchmarks/gpu_posterior.sh STAGE [RUN_DIR]; logs and results go to $OUT
# (default out/benchmarks/posterior, outside git; not benchmarks/results).
# SMOKE=1 shrinks everything to check the script on a CPU.
set -euo pipefail
stage=${1:?stage: calibration, paper, latency, measured, members, ensemble, coverage or joint}
R=${2:-/tmp/posterior_run}
OUT=${OUT:-out/benchmarks/posterior}
mkdir -p "$R" "$OUT"
export PYTHONUNBUFFERED=1
GI=gray_interlock
if [ -n "${SMOKE:-}" ]; then
  CAL="--preset=smoke --backend=c"
  DS="--preset=smoke --materials=$GI --sequences=4"
  TR="--preset=smoke"
  EV="--preset=smoke --materials=$GI --sequences=2 --resolution=32 --frames=8 --cloth_resolution=8"
  EST="--preset=smoke --backend=c"
  LAT="--backend=c --settings=psd_smoke --repeats=1"
else
  CAL="--backend=mjx"
  DS="--materials=$GI --batch_size=30"
  TR="--val_fraction=0.2 --patience=4"
  EV="--preset=eval --materials=$GI --sequences=${NREC:-3} --batch_size=${NREC:-3}"
  EST=""
  LAT="--backend=mjx --settings=psd${PAPER:+,paper} --repeats=1"
fi
case "$stage" in
  calibration)
    python -m experiments.calibrate --workdir="$R/calibration" $CAL 2>&1 | tee "$OUT/calibration.log"
    cp "$R"/calibration/calibration.json "$R"/calibration/calibration.md \
      "$R"/calibration/*.png "$OUT/"
    ;;
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
  measured)
    pre=default; [ -n "${SMOKE:-}" ] && pre=smoke
    for m in wind_reading_sd area_weight_reading_sd; do
      python -m experiments.tables --eval="$R/eval" --models="$R/t1" --workdir="$R/tables_$m" \
        --methods=physnet_depth --preset=$pre ${EST:+--backend=c} --$m=0.02 2>&1 | tail -30 \
        | tee "$OUT/tables_$m.log"
      cp "$R/tables_$m/tables.json" "$OUT/tables_$m.json"
    done
    python -m benchmarks.measured_modes --measured_sd=0.02 --out="$OUT/measured_modes.json" \
      --estimates="$R/tables_default/physnet_depth/fabrics/$GI-*" 2>&1 | tee "$OUT/measured_modes.log"
    ;;
  members)
    for s in $(seq 1 "${MEMBERS:-2}"); do
      python -m experiments.train --dataset="$R/ds" --workdir="$R/t1_s$s/physnet_depth/simulation" \
        --materials=$GI $TR --seed="$s" 2>&1 | tail -2 | tee "$OUT/train_s$s.log"
    done
    ;;
  ensemble)
    pre=default; [ -n "${SMOKE:-}" ] && pre=smoke
    roots=$R/t1
    for s in $(seq 1 "${MEMBERS:-2}"); do roots="$roots,$R/t1_s$s"; done
    for m in ${ENSEMBLE_MODES:-wind_reading_sd none}; do
      read_flag=""; [ "$m" != none ] && read_flag="--$m=0.02"
      python -m experiments.tables --eval="$R/eval" --models="$roots" --workdir="$R/ensemble_$m" \
        --methods=physnet_depth --preset=$pre ${EST:+--backend=c} $read_flag 2>&1 | tail -30 \
        | tee "$OUT/ensemble_$m.log"
      cp "$R/ensemble_$m/tables.json" "$OUT/ensemble_$m.json"
    done
    if [ -n "${SINGLES-1}" ]; then
      pids=""
      for root in ${roots//,/ }; do
        name=$(basename "$root")
        XLA_PYTHON_CLIENT_MEM_FRACTION=0.3 \
        python -m experiments.tables --eval="$R/eval" --models="$root" --workdir="$R/single_${name}_wind" \
          --methods=physnet_depth --preset=$pre ${EST:+--backend=c} --wind_reading_sd=0.02 \
          > "$OUT/single_${name}_wind.log" 2>&1 &
        pids="$pids $!"
      done
      for p in $pids; do wait "$p"; done
      for root in ${roots//,/ }; do
        name=$(basename "$root")
        tail -30 "$OUT/single_${name}_wind.log"
        cp "$R/single_${name}_wind/tables.json" "$OUT/single_${name}_wind.json"
      done
    fi
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
  joint)
    pre=default; [ -n "${SMOKE:-}" ] && pre=smoke
    name=joint_${GROUP:-3}${DISTANCE:+_$DISTANCE}${LIKELIHOOD:+_$LIKELIHOOD}${GUSTS:+_g$GUSTS}${CLOTH:+_c$CLOTH}${SECONDS_CLIP:+_${SECONDS_CLIP}s}
    model="--model=$R/t1/physnet_depth/simulation/$GI"
    [ "${DISTANCE:-}" = shape ] && model="--image_size=$([ -n "${SMOKE:-}" ] && echo 32 || echo 256)"
    python -m benchmarks.joint_pairs "$model" \
      --workdir="$R/$name" --pairs="${NGROUPS:-8}" --group="${GROUP:-3}" --preset=$pre \
      ${SMOKE:+--smoke --backend=c} --distance="${DISTANCE:-energy}" \
      ${LIKELIHOOD:+--likelihood=$LIKELIHOOD} ${SHARPNESS:+--sharpness=$SHARPNESS} \
      ${GUSTS:+--gusts=$GUSTS} ${CLOTH:+--cloth_resolution=$CLOTH} \
      ${SECONDS_CLIP:+--seconds=$SECONDS_CLIP} 2>&1 | tail -12 \
      | tee "$OUT/$name.log"
    cp "$R/$name/joint_pairs.json" "$OUT/$name.json"
    ;;
  *) echo "unknown stage $stage"; exit 2 ;;
esac
