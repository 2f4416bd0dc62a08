#!/usr/bin/env bash
# Render one rig on a Slurm farm: one array task per chunk of frames, then a merge job that
# starts only when every chunk task succeeded (afterok). See README.md beside this file.
#
#   examples/farm/submit.sh RIG OUT [CHUNKS [PREROLL]]
#
# RIG, OUT, CHUNKS and PREROLL may also come from FARM_RIG, FARM_OUT, FARM_CHUNKS (default 8)
# and FARM_PREROLL (default: furrow's own). Other settings, all optional:
#   FURROW             the furrow binary on the compute nodes (default: furrow on PATH)
#   FARM_FRAMES        A:B, only these frames of the clip (passed to `furrow chunks --frames`)
#   FARM_CPUS          CPUs per chunk task (over chunk.sbatch's --cpus-per-task)
#   FARM_MEM           memory per chunk task, e.g. 8G (over chunk.sbatch's --mem)
#   FARM_MERGE_CPUS    CPUs of the merge job (over merge.sbatch's --cpus-per-task)
#   FARM_MERGE_MEM     memory of the merge job (over merge.sbatch's --mem)
#   FARM_MAX_RUNNING   at most this many chunk tasks at once (--array=...%K)
#   FARM_SBATCH_ARGS   more sbatch options for both jobs, e.g. "--partition=render --time=2:00:00"
# RIG, OUT and FURROW must be on a filesystem every node sees. Prints `array JOBID` and
# `merge JOBID`; the result is OUT/<rig>_wrinkled.glb, the job logs are in OUT/logs/.
set -euo pipefail

usage() { echo "usage: $0 RIG OUT [CHUNKS [PREROLL]]" >&2; exit 2; }
rig=${1:-${FARM_RIG:-}}
out=${2:-${FARM_OUT:-}}
count=${3:-${FARM_CHUNKS:-8}}
preroll=${4:-${FARM_PREROLL:-}}
[ -n "$rig" ] && [ -n "$out" ] || usage
[[ $count =~ ^[1-9][0-9]*$ ]] || { echo "$0: CHUNKS must be a positive integer, not '$count'" >&2; exit 2; }
[ -z "$preroll" ] || [[ $preroll =~ ^[0-9]+$ ]] || { echo "$0: PREROLL must be a frame count, not '$preroll'" >&2; exit 2; }
[ -f "$rig" ] || { echo "$0: no rig file $rig" >&2; exit 2; }

here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out/logs"
# Absolute paths: the jobs run in OUT on other nodes.
rig=$(cd "$(dirname "$rig")" && pwd)/$(basename "$rig")
out=$(cd "$out" && pwd)
furrow=${FURROW:-furrow}
if [[ $furrow == */* ]]; then
  furrow=$(cd "$(dirname "$furrow")" && pwd)/$(basename "$furrow")
fi
export FURROW=$furrow

# The chunk ranges, balanced by expected cost; one A:B a line.
"$furrow" chunks "$rig" --count "$count" ${preroll:+--preroll "$preroll"} \
  ${FARM_FRAMES:+--frames "$FARM_FRAMES"} > "$out/ranges.txt"
n=$(grep -c . "$out/ranges.txt" || true)
if [ "$n" -lt 1 ] || grep -vqE '^[0-9]+:[0-9]+$' "$out/ranges.txt"; then
  echo "$0: furrow chunks gave no usable ranges (see $out/ranges.txt)" >&2
  exit 1
fi

# Extra sbatch options (word-split on purpose: "--partition=render --time=2:00:00").
read -r -a extra <<< "${FARM_SBATCH_ARGS:-}"
chunk_opts=(--chdir="$out" --array="0-$((n - 1))${FARM_MAX_RUNNING:+%$FARM_MAX_RUNNING}")
[ -z "${FARM_CPUS:-}" ] || chunk_opts+=(--cpus-per-task="$FARM_CPUS")
[ -z "${FARM_MEM:-}" ] || chunk_opts+=(--mem="$FARM_MEM")
merge_opts=(--chdir="$out")
[ -z "${FARM_MERGE_CPUS:-}" ] || merge_opts+=(--cpus-per-task="$FARM_MERGE_CPUS")
[ -z "${FARM_MERGE_MEM:-}" ] || merge_opts+=(--mem="$FARM_MERGE_MEM")

array_id=$(sbatch --parsable "${extra[@]}" "${chunk_opts[@]}" \
  "$here/chunk.sbatch" "$rig" "$out" "$preroll")
array_id=${array_id%%;*} # --parsable prints JOBID[;CLUSTER]
# The merge waits for every task of the array to end with exit code 0. If one fails, the
# dependency can never be met and --kill-on-invalid-dep cancels the merge (instead of leaving
# it pending with reason DependencyNeverSatisfied).
merge_id=$(sbatch --parsable "${extra[@]}" "${merge_opts[@]}" \
  --dependency="afterok:$array_id" --kill-on-invalid-dep=yes \
  "$here/merge.sbatch" "$rig" "$out")
merge_id=${merge_id%%;*}
echo "array $array_id"
echo "merge $merge_id"
echo "$n chunk tasks ($out/ranges.txt); result: $out/$(basename "${rig%.*}")_wrinkled.glb" >&2
