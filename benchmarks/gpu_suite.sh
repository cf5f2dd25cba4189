#!/usr/bin/env bash
# The GPU measurements behind BENCHMARKS.md, in the order they are run on the
# device machine (after the wheels of ../shared/tools/device-wheels.sh are in
# /tmp/site). Each step has its own time limit and log under $OUT (default
# out/benchmarks/suite, outside git; not benchmarks/results); a failing
# step does not stop the rest.
#   bash benchmarks/gpu_suite.sh render|motion|estimate|tables
# The device image had no working EGL: MuJoCo's own renderer is timed on the CPU
# only (render_throughput.py there), and MUJOCO_GL=glfw lets mujoco import.
set -uo pipefail
export PYTHONPATH=${PYTHONPATH:+$PYTHONPATH:}$PWD PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
OUT=${OUT:-out/benchmarks/suite}
mkdir -p "$OUT"
step() {  # name seconds command...
  local name=$1 secs=$2
  shift 2
  local t0=$SECONDS
  timeout "$secs" "$@" >"$OUT/$name.log" 2>&1
  echo "$name: exit $? in $((SECONDS - t0)) s"
}
case ${1:-render} in
  render)
    nvidia-smi -L >"$OUT/gpu.txt" 2>&1
    step render_raster 200 python -m benchmarks.render_throughput \
      --batch_sizes=1,16,64,210 --methods=raster --mjwarp --mujoco_frames=0 \
      --out="$OUT/render_gpu.json"
    step render_brute 60 python -m benchmarks.render_throughput \
      --batch_sizes=1 --methods=brute --mujoco_frames=0 \
      --out="$OUT/render_brute_gpu.json"
    step train_fp32 150 python -m benchmarks.train_throughput --precision=float32 \
      --out="$OUT/train_gpu.json"
    step train_bf16 100 python -m benchmarks.train_throughput --precision=bfloat16 \
      --out="$OUT/train_gpu_bf16.json"
    ;;
  motion)
    step motion 330 python -m experiments.fabric_motion --workdir="$OUT/motion" \
      --backend=mjx
    step dataset 250 python -m experiments.generate_dataset --out=/tmp/ds \
      --batch_size=210
    cp /tmp/ds/summary.json "$OUT/dataset_summary.json" 2>/dev/null
    cp /tmp/ds/montage_*.png "$OUT/" 2>/dev/null
    ;;
  estimate)
    step train 240 python -m experiments.train --dataset=/tmp/ds \
      --workdir=/tmp/train --materials=gray_interlock --epochs=6
    cp /tmp/train/gray_interlock/metrics.jsonl "$OUT/train_metrics.jsonl" 2>/dev/null
    step eval_set 90 python -m experiments.generate_dataset --preset=eval \
      --out=/tmp/eval --materials=gray_interlock
    step estimate 220 python -m experiments.estimate \
      --recording=/tmp/eval/gray_interlock/0000 --material=gray_interlock \
      --model=/tmp/train/gray_interlock --workdir="$OUT/estimate"
    ;;
  tables)  # the partial Table 2 in README (after 'motion' made /tmp/ds)
    step train 420 python -m experiments.train --dataset=/tmp/ds \
      --workdir=/tmp/models/physnet_depth/simulation --epochs=5
    step eval_set 200 python -m experiments.make_eval_set --out=/tmp/eval \
      --sequences=2
    # Resumable: rerun until every recording has its estimate.json.
    step tables 530 python -m experiments.tables --eval=/tmp/eval \
      --models=/tmp/models --workdir=/tmp/tables --methods=physnet_depth --preset=paper
    cp /tmp/tables/tables.md /tmp/tables/tables.json "$OUT/" 2>/dev/null
    ;;
esac
tail -n 3 "$OUT"/*.log
