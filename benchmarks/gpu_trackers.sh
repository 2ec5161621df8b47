#!/usr/bin/env bash
# The trackers' GPU figures in one call of at most ~8 minutes (it fits the device
# tool's 10-minute command limit), each step a benchmarks/real_data.py command:
#
#  1. time to the first tracked pose on Replica room0, the paper's settings with the
#     fast first frame (TSDF warm start + 30 steps at 2x) and the hybrid tracker, run
#     twice in one process: the first run pays CUDA's start-up (context, kernels'
#     first launches), the second shows a warm process;
#  2. 7-Scenes redkitchen frames 0-399 with the ScanNet settings
#     (configs/sevenscenes/redkitchen.yaml) and each tracker (render, sdf, hybrid),
#     the three runs side by side on the one GPU, each budgeted to BUDGET minutes
#     (a 20-frame probe, then resumed up to the frames that fit; real_data.py).
#
#     bash benchmarks/gpu_trackers.sh DATA_ROOT OUT [BUDGET_MIN] [DEVICE] [MAX_FRAMES]
#
# DATA_ROOT holds 7scenes-redkitchen/ and replica-room0/ (as ../shared/data does);
# OUT receives one log per step (each ends with real_data.py's markdown table) and
# runs.tgz (the run folders without maps and meshes). DEVICE defaults to cuda;
# MAX_FRAMES caps every run (a smoke test on the CPU: ... OUT 1 cpu 3).
set -u
data=${1:?usage: gpu_trackers.sh DATA_ROOT OUT [BUDGET_MIN] [DEVICE] [MAX_FRAMES]}
out=${2:?usage: gpu_trackers.sh DATA_ROOT OUT [BUDGET_MIN] [DEVICE] [MAX_FRAMES]}
budget=${3:-6.5}
device=${4:-cuda}
room0_frames=${5:-16}
cap=()
if [ -n "${5:-}" ]; then cap=(--max-frames "$5"); fi
export PYTHONUNBUFFERED=1
export PYTHONPATH="$(cd "$(dirname "$0")/.." && pwd)${PYTHONPATH:+:$PYTHONPATH}"
here=$(cd "$(dirname "$0")" && pwd)
runs=$(mktemp -d)
mkdir -p "$out"
limit_s=$(python3 -c "print(int($budget * 60 + 90))")

{
  nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>&1 || true
  python3 -c "import torch; print('torch', torch.__version__)"
  timeout 300 python3 "$here/real_data.py" --device "$device" --threads 4 --data-root "$data" \
    --cases room0-paper --methods hybrid hybrid --max-frames "$room0_frames" \
    --out "$runs/room0" --no-append \
    --note "time to the first tracked pose, fast first frame on the paper settings; the second row ran in the same process after the first" \
    mapping.first_warm_start=tsdf mapping.first_iterations=30 mapping.first_lr_factor=2.0
} >"$out/room0.log" 2>&1

for method in hybrid render sdf; do
  timeout "$limit_s" python3 "$here/real_data.py" --device "$device" --threads 4 \
    --data-root "$data" --cases redkitchen-scannet --methods "$method" \
    --budget-min "$budget" "${cap[@]}" --out "$runs/redkitchen" --no-append \
    --note "render, sdf and hybrid side by side on the one device (benchmarks/gpu_trackers.sh)" \
    >"$out/redkitchen-$method.log" 2>&1 &
done
wait
tar czf "$out/runs.tgz" --exclude='*.pt' --exclude='*.ply' -C "$runs" .
