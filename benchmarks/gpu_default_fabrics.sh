#!/usr/bin/env bash
# The estimate's defaults as a user runs them, one recording of each fabric
# (issue 41: a default paper-size estimate of any of the 7 fabrics quotes
# measured coverage, never "indicative"). Recordings of another physics (the
# evaluation recipe under physsim.mismatch.WORLD), then one process per
# recording of `python -m experiments.estimate` given only the recording, its
# fabric and a workdir, timed from the shell (the first with cold caches).
#
#   bash benchmarks/gpu_default_fabrics.sh make R          # the recordings
#   bash benchmarks/gpu_default_fabrics.sh estimate R [FABRIC ...]   # default: all 7
#   python -m benchmarks.default_fabrics --root=R          # the table and JSON
#
# Writes R/times.txt (fabric, exit status, milliseconds) and R/<fabric>.log.
# shellcheck shell=bash
set -u
stage=$1 R=$2
shift 2
export PYTHONPATH=${PYTHONPATH:+$PYTHONPATH:}$PWD PYTHONUNBUFFERED=1
mkdir -p "$R"
case "$stage" in
  make)
    python -m experiments.generate_dataset --preset=eval --sequences=1 \
      --physics=mismatched --out="$R/recordings" 2>&1 | tail -3
    ;;
  estimate)
    fabrics=("$@")
    [ ${#fabrics[@]} -eq 0 ] && fabrics=(white_tablecloth gray_interlock black_denim \
      sparkle_fleece pink_nylon ponte_roma red_violet)
    for f in "${fabrics[@]}"; do
      t=$(date +%s%N)
      python -m experiments.estimate --recording="$R/recordings/$f/0000" \
        --material="$f" --workdir="$R/est_$f" >"$R/$f.log" 2>&1
      rc=$?
      echo "$f rc=$rc $((($(date +%s%N) - t) / 1000000)) ms" | tee -a "$R/times.txt"
    done
    ;;
  *) echo "unknown stage $stage: make or estimate" >&2; exit 2 ;;
esac
