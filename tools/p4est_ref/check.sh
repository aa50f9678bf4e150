#!/bin/sh
# Self-test: balanced leaves and node counts must not depend on the rank
# count, and text and binary input must give the same result.
set -eu
here=$(cd "$(dirname "$0")" && pwd)
bin="$here/octmesh_p4est"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
MPIRUN=${MPIRUN:-mpirun --oversubscribe}
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1

python3 "$here/gen_test_leaves.py" "$tmp/t.txt" >/dev/null
python3 "$here/gen_test_leaves.py" "$tmp/t.bin" >/dev/null

# Keys that must agree between runs (timings and memory vary).
counts() {
  python3 -c 'import json,sys; d=json.load(open(sys.argv[1]))
for k in ("tool","timings","peak_rss_bytes","ranks","repeat"): d.pop(k,None)
for k in [k for k in d if k.startswith("rss_")]: d.pop(k)
print(json.dumps(d, sort_keys=True))' "$1"
}

for b in none face edge corner; do
  nodes=""
  [ "$b" = edge ] || [ "$b" = corner ] && nodes=--nodes
  for np in 1 2 3 4; do
    for fmt in txt bin; do
      $MPIRUN -np $np "$bin" --in "$tmp/t.$fmt" --balance $b $nodes \
        --out "$tmp/o_${b}_$np.$fmt" --json "$tmp/j_${b}_${np}_$fmt.json" \
        --repeat 3 >/dev/null
      counts "$tmp/j_${b}_${np}_$fmt.json" >"$tmp/c_${b}_${np}_$fmt"
      cmp -s "$tmp/c_${b}_${np}_$fmt" "$tmp/c_${b}_1_txt" ||
        { echo "FAIL: counts differ ($b, np=$np, $fmt)"; exit 1; }
      cmp -s "$tmp/o_${b}_$np.$fmt" "$tmp/o_${b}_1.$fmt" ||
        { echo "FAIL: leaves differ ($b, np=$np, $fmt)"; exit 1; }
    done
  done
  echo "ok $b: $(cat "$tmp/c_${b}_1_txt")"
done

# Binary output read back and rewritten as text must equal the text output.
$MPIRUN -np 2 "$bin" --in "$tmp/o_corner_1.bin" --balance none \
  --out "$tmp/rt.txt" >/dev/null
cmp -s "$tmp/rt.txt" "$tmp/o_corner_1.txt" ||
  { echo "FAIL: binary and text outputs differ"; exit 1; }
echo "ok binary/text round trip"
