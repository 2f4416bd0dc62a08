#!/usr/bin/env bash
# A stand-in for furrow to try the farm scripts without the physics (tests/farm_slurm.rs uses
# it): FURROW=examples/farm/furrow-stub.sh examples/farm/submit.sh RIG OUT 4
#   chunks RIG --count N [--preroll P] [--frames A:B]   splits FURROW_STUB_FRAMES (default
#                                                       12) frames, or A:B, into N ranges
#   animate RIG --frames A:B ... -o DIR/part_A_B.glb    writes the .glb and .furrow-chunk
#                                                       after FURROW_STUB_SECONDS (default 1);
#                                                       fails (exit 2) when A:B is FURROW_FAIL_RANGE
#   merge CHUNK... --rig RIG -o OUT.glb [--report R]    writes OUT.glb listing the chunks
set -euo pipefail
cmd=${1:?usage: furrow-stub.sh chunks|animate|merge ...}
shift
rig= count=1 preroll=0 frames= output= report= inputs=()
while [ $# -gt 0 ]; do
  case $1 in
    --count) count=$2; shift ;;
    --preroll) preroll=$2; shift ;;
    --frames) frames=$2; shift ;;
    -o | --output) output=$2; shift ;;
    --report) report=$2; shift ;;
    --rig) rig=$2; shift ;;
    --quiet | --force) ;;
    -*) echo "furrow-stub: unknown option $1" >&2; exit 2 ;;
    *) if [ -z "$rig" ] && [ "$cmd" != merge ]; then rig=$1; else inputs+=("$1"); fi ;;
  esac
  shift
done
case $cmd in
  chunks)
    a=0 b=${FURROW_STUB_FRAMES:-12}
    [ -z "$frames" ] || { a=${frames%%:*}; b=${frames##*:}; }
    for ((i = 0; i < count; i++)); do
      echo "$((a + (b - a) * i / count)):$((a + (b - a) * (i + 1) / count))"
    done
    ;;
  animate)
    [ -f "$rig" ] || { echo "furrow-stub: no rig $rig" >&2; exit 2; }
    sleep "${FURROW_STUB_SECONDS:-1}"
    if [ "$frames" = "${FURROW_FAIL_RANGE:-}" ]; then
      echo "furrow-stub: frames $frames fail on purpose (FURROW_FAIL_RANGE)" >&2
      exit 2
    fi
    echo "stub glb frames=$frames" > "$output"
    printf 'frames=%s preroll=%s threads=%s task=%s\n' "$frames" "$preroll" \
      "${RAYON_NUM_THREADS:-}" "${SLURM_ARRAY_TASK_ID:-}" > "${output%.glb}.furrow-chunk"
    ;;
  merge)
    for c in "${inputs[@]}"; do
      [ -f "$c" ] || { echo "furrow-stub: missing chunk $c" >&2; exit 2; }
    done
    cat "${inputs[@]}" > "$output"
    [ -z "$report" ] || echo "{\"chunks\": ${#inputs[@]}}" > "$report"
    ;;
  *) echo "furrow-stub: unknown command $cmd" >&2; exit 2 ;;
esac
