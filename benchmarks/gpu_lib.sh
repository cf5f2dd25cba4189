# Shared by the GPU job scripts (sourced after setting R): training defaults,
# status lines, timed steps, and the launcher that runs one program as one
# process per GPU (jax.distributed). Every step is one program over every GPU
# of the machine: a single process splits its worlds over all local devices
# (physsim.devices); LAUNCH runs NG processes, one per GPU, that share the
# independent jobs (trainings, recordings). Set PYTHONPATH yourself if the
# project's dependencies live outside the interpreter (e.g. carried wheels).
# shellcheck shell=bash
# Training defaults: at most EPOCHS epochs, the epoch chosen on VAL of the
# training simulations, stopping after PATIENCE epochs without a better one.
EPOCHS=${EPOCHS:-30}
VAL=${VAL:-0.2}
PATIENCE=${PATIENCE:-4}
export PYTHONPATH=${PYTHONPATH:+$PYTHONPATH:}$PWD PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
NG=${NG:-$(nvidia-smi -L 2>/dev/null | wc -l)}
[ "$NG" -ge 1 ] 2>/dev/null || NG=1
FABRICS=(white_tablecloth gray_interlock black_denim sparkle_fleece pink_nylon ponte_roma red_violet)
T1_ARGS="--epochs=$EPOCHS --val_fraction=$VAL --patience=$PATIENCE"
# Table 1 columns = Tables 2/3 methods a job trains and estimates (default: all four).
COLUMNS=${COLUMNS:-sdn_rgb,sdn_depth,physnet_rgb,physnet_depth}
if [ -n "${SMOKE:-}" ]; then  # tiny settings for checking a script on a CPU
  FABRICS=(gray_interlock black_denim)
  T1_ARGS="--preset=smoke --epochs=3 --val_fraction=$VAL --patience=1 --test_fraction=0.2"
fi
mkdir -p "$R/logs"
T0=$SECONDS
note() { echo "$((SECONDS - T0)) s: $*" >>"$R/status.txt"; }
step() {  # name seconds command...
  local name=$1 secs=$2
  shift 2
  local t=$SECONDS
  timeout "$secs" "$@" >"$R/logs/$name.log" 2>&1
  local rc=$?
  note "$name: exit $rc in $((SECONDS - t)) s"
  return $rc
}
# One program over every GPU: NG processes joined by jax.distributed, one GPU each
# (on a CPU smoke run the processes share the CPU).
GPP=1
[ -n "${SMOKE:-}" ] && GPP=0
# e.g. step NAME SECS "${LAUNCH[@]}" --command="python -m experiments.tables ..."
LAUNCH=(python -m experiments.launch --processes="$NG" --gpus_per_process="$GPP")
