#!/usr/bin/env bash
# Before/after on the demo scene: `eslam run configs/demo.yaml` from two checkouts, one
# after the other on the same data, printing wall time, ATE and FPT of each.
#   bash benchmarks/ab_demo.sh OLD_CHECKOUT NEW_CHECKOUT DEMO_DATA OUT
# DEMO_DATA is a demo scene folder (`eslam demo` writes one to OUT/data). Both checkouts
# run in this environment's Python with PYTHONPATH set to the checkout.
set -euo pipefail
old=$1; new=$2; data=$3; out=$4
export OMP_WAIT_POLICY=PASSIVE
bound=$(python -c "import json,sys; print(json.load(open(sys.argv[1]))['bound'])" "$data/synth.json")
for side in old new; do
  src=${!side}
  rm -rf "$out/$side"
  start=$(date +%s.%N)
  (cd "$src" && PYTHONPATH="$src" python -m eslam.cli run "$src/eslam/configs/demo.yaml" \
    --data "$data" --out "$out/$side" "scene.bound=$bound" output.progress=false > "$out/$side.log" 2>&1)
  end=$(date +%s.%N)
  python - "$side" "$start" "$end" "$out/$side/metrics.json" <<'PY'
import json, sys
side, start, end, path = sys.argv[1:]
m = json.load(open(path))
print(f"{side}: wall {float(end) - float(start):.1f} s, ATE {m['ate_rmse_cm']!r} cm, FPT {m['fpt_s']:.3f} s")
PY
done
