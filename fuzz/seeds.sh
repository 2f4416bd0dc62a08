#!/usr/bin/env bash
# Seeds for the loader's fuzz target, generated here (never copied in from outside): gltfpack
# copies of ../shared/data/ (quantized only, quantized + meshopt, meshopt at 12-bit positions)
# and furrow's own compact output (the capture-shaped head, and the wrinkle layers of the
# shared files and rigs, plain, quantized and compressed, that tests/io_layer_writer.rs writes).
# Usage: fuzz/seeds.sh [DIR] (default fuzz/corpus/load, which git ignores). Needs the Node tools
# (npm ci --prefix .ci) and ../shared/data/.
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${1:-fuzz/corpus/load}
mkdir -p "$dir"
pack=.ci/node_modules/gltfpack/cli.js
for f in ../shared/data/*.glb; do
  n=$(basename "$f" .glb)
  node "$pack" -kn -km -ke -i "$f" -o "$dir/${n}_q.glb" >/dev/null
  node "$pack" -cc -kn -km -ke -i "$f" -o "$dir/${n}_cc.glb" >/dev/null
  node "$pack" -c -vp 12 -kn -km -ke -i "$f" -o "$dir/${n}_c12.glb" >/dev/null
done
cargo run --release --quiet -- rig generate --kind head -o "$dir/furrow_head.glb" --force --quiet
FURROW_SEEDS_DIR="$(cd "$dir" && pwd)" cargo test --release --quiet --test io_layer_writer -- layers_of >/dev/null
# Large inputs make slow executions: keep seeds up to 256 KB (run with -max_len=262144).
find "$dir" -name '*.glb' -size +256k -delete
ls "$dir" | wc -l
