# The demo-size misplaced-camera study of BENCHMARKS.md; run from the project root
# with the project installed (README). Writes under out/.
set -e
mkdir -p out
export PYTHONUNBUFFERED=1
W=out/camstudy
python -m experiments.demo --workdir=out/demo > $W.demo.log 2>&1
mkdir -p $W/t1/physnet_depth/simulation
ln -sfn $PWD/out/demo/model/gray_interlock $W/t1/physnet_depth/simulation/gray_interlock
python -m experiments.generate_dataset --preset=eval --materials=gray_interlock --sequences=12 --batch_size=12 \
  --frames=20 --warmup=0.5 --cloth_resolution=13 --resolution=32 --seed=2000 --backend=c --out=$W/eval/fabrics > $W.eval.log 2>&1
EST="--methods=physnet_depth --cloth_resolution=10 --frames=16 --warmup=0.5 --q=8 --n_init=16 --max_iter=6 --backend=c --reading_seed=7"
run() { name=$1; shift; python -m experiments.tables --eval=$W/eval --models=$W/t1 --workdir=$W/$name $EST "$@" > $W/$name.log 2>&1; echo "$name done $(date)"; }
run shape_exact --distance=shape
run shape_misplaced --distance=shape --camera_error_m=0.02 --camera_error_deg=3
run shape_misplaced_modelled --distance=shape --camera_error_m=0.02 --camera_error_deg=3 --camera_sd_m=0.02 --camera_sd_deg=3
