# Helpers of the multi-GPU job scripts (sourced; they set R, T0, NG, FABRICS
# and T1 first): status lines, timed steps per GPU, and a task queue that the
# GPUs pull from.
# shellcheck shell=bash
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
make_queue() {  # $1: split; the columns in $COLUMNS (default: all four)
  local m c n cols=",${COLUMNS:-sdn_rgb,sdn_depth,physnet_rgb,physnet_depth},"
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

