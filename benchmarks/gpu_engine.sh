#!/usr/bin/env bash
# The simulator and renderer on one GPU (issue 21), each step alone on the GPU:
#   1. the project's rollouts ('warp', 'mjx') beside MuJoCo Warp called directly
#      on the same model (physsim_throughput --direct) at 210 and 1024 worlds,
#      each also with the direct run's forces (--ablate_forces), where each part
#      of a step goes (--event_trace), and the paper dataset's 210 x (1+3) s in
#      one call;
#   2. the solver's knobs at 1024 worlds on 'warp': CG tolerance 1e-6 and 1e-5
#      (MuJoCo's 1e-8 never stops early in float32);
#   3. rendering 210 worlds x 6 cameras x 60 frames at 256 px (chunks sized from
#      free memory).
# Usage: OUT=/path bash benchmarks/gpu_engine.sh; logs and JSON go to $OUT
# (default out/benchmarks/engine, outside git; not benchmarks/results).
# SMOKE=1 checks the script on a CPU with tiny sizes.
set -uo pipefail
OUT=${OUT:-out/benchmarks/engine}
mkdir -p "$OUT"
export PYTHONPATH=${PYTHONPATH:+$PYTHONPATH:}$PWD PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
step() {  # name seconds command...
  local name=$1 secs=$2 t0=$SECONDS
  shift 2
  timeout "$secs" "$@" >"$OUT/$name.log" 2>&1
  echo "$name: exit $? in $((SECONDS - t0)) s"
}
P="benchmarks/physsim_throughput.py --c_baseline=false"
B1=210 B2=1024 R=256 RB=210 PD=--paper_dataset
if [ -n "${SMOKE:-}" ]; then
  P="$P --resolution=8 --seconds=0.05 --repeats=1"
  B1=2 B2=4 R=32 RB=3 PD=
fi
step direct 400 python $P --batch_sizes=$B1,$B2 --direct --backends=warp,mjx \
  --ablate_forces --event_trace $PD --out="$OUT/physsim_direct.json"
for tol in 1e-6 1e-5; do
  step "tolerance_$tol" 90 python $P --batch_sizes=$B2 --backends=warp \
    --tolerance=$tol --out="$OUT/physsim_tolerance_$tol.json"
done
step render 120 python -m benchmarks.render_throughput --batch_sizes=$RB \
  --methods=raster --mujoco_frames=0 --repeats=1 --resolution=$R \
  ${SMOKE:+--frames=4 --cameras=2} --out="$OUT/render_210.json"
grep -h "^|" "$OUT"/*.log
