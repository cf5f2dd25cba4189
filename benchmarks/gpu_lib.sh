# Shared by the multi-GPU job scripts (sourced after setting R; they set T1
# before using the queue): training defaults, status lines, timed steps per
# GPU, and a task queue that the GPUs pull from.
# shellcheck shell=bash
# Training defaults: at most EPOCHS epochs, the epoch chosen on VAL of the
# training simulations, stopping after PATIENCE epochs without a better one.
EPOCHS=${EPOCHS:-30}
VAL=${VAL:-0.2}
PATIENCE=${PATIENCE:-4}
export PYTHONPATH=${PYTHONPATH:-/tmp/site:$PWD} PYTHONUNBUFFERED=1 MUJOCO_GL=${MUJOCO_GL:-glfw}
NG=${NG:-$(nvidia-smi -L | wc -l)}
FABRICS=(white_tablecloth gray_interlock black_denim sparkle_fleece pink_nylon ponte_roma red_violet)
T1_ARGS="--epochs=$EPOCHS --val_fraction=$VAL --patience=$PATIENCE"
# Table 1 columns = Tables 2/3 methods a job trains and estimates (default: all four).
COLUMNS=${COLUMNS:-sdn_rgb,sdn_depth,physnet_rgb,physnet_depth}
if [ -n "${SMOKE:-}" ]; then  # tiny settings for checking a script on a CPU
  FABRICS=(gray_interlock black_denim)
  T1_ARGS="--preset=smoke --epochs=3 --val_fraction=$VAL --patience=1 --test_fraction=0.2"
fi
mkdir -p "$R/logs" "$R/queue"
T0=$SECONDS
note() { echo "$((SECONDS - T0)) s: $*" >>"$R/status.txt"; }
step() {  # gpu name seconds command...
  local gpu=$1 name=$2 secs=$3
  shift 3
  local t=$SECONDS
  CUDA_VISIBLE_DEVICES=$((gpu % NG)) timeout "$secs" "$@" >"$R/logs/$name.log" 2>&1
  local rc=$?
  note "$name (gpu $((gpu % NG))): exit $rc in $((SECONDS - t)) s"
  return $rc
}
wait_for() { while [ ! -e "$1" ]; do sleep 5; done; }
# The queue: "name columns split materials" per line, longest tasks first.
pairs() { local i; for ((i = 0; i < ${#FABRICS[@]}; i += $1)); do
  local s=("${FABRICS[@]:i:$1}"); (IFS=,; echo "${s[*]}"); done; }
make_queue() {  # $1: split; the columns in $COLUMNS
  local m c n cols=",$COLUMNS,"
  # column:fabrics per task, the longest tasks first
  for c in sdn_rgb:1 sdn_depth:2 physnet_rgb:2 physnet_depth:3; do
    n=${c#*:} c=${c%:*}
    [[ $cols == *",$c,"* ]] || continue
    for m in $(pairs "$n"); do echo "${c}_$1_${m//,/_} $c $1 $m"; done
  done
}
pop() {  # $1: queue; prints the next task's line (empty when none is left)
  (
    flock 9
    local n line
    n=$(cat "$R/queue/$1.next" 2>/dev/null || echo 1)
    line=$(sed -n "${n}p" "$R/queue/$1.txt")
    [ -n "$line" ] && echo $((n + 1)) >"$R/queue/$1.next"
    echo "$line"
  ) 9>"$R/queue/$1.lock"
}
drain() {  # gpu queue timeout: run tasks until the queue is empty
  local g=$1 q=$2 secs=$3 line name cols split mats
  while line=$(pop "$q") && [ -n "$line" ]; do
    read -r name cols split mats <<<"$line"
    step "$g" "t1_$name" "$secs" $T1 --columns="$cols" --splits="$split" \
      --materials="$mats" && touch "$R/queue/$name.done"
    touch "$R/queue/$name.ended"
  done
}
all_ended() {  # queue: wait until every task of it has ended
  local name
  for name in $(cut -d' ' -f1 "$R/queue/$1.txt"); do wait_for "$R/queue/$name.ended"; done
}

