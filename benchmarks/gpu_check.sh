#!/usr/bin/env bash
# The GPU checks of issue 26, in one script for one GPU (sized for an H200: about 8 minutes). Writes under $OUT:
#   bench.json          `repro bench update` plain, amp and fast at B256 and B1024 (TACO, DrQ-v2), and the e2e entries of
#                       a 10K-frame TACO B1024 run (4000 seed frames, 6000 timed), plain and fast (agent.fast), each
#                       timed phase by phase and as it trains (--overlap: the env step overlapping the queued update)
#   graphs.xml          tests/test_graphs.py on the GPU (JUnit): the CUDA-graph update (agent.fast) against eager
#   bench-compile.json  `repro bench update --compile` at B256 and B1024 (last: it takes what time is left)
#   amp_check.json      plain against amp: the losses of 5 updates from the same weights and batches
#   fast_check.json     plain against fast (agent.fast): the same
#   packing.json        2 and 4 runs sharing GPU 0 (`repro sweep --gpus 0 --runs-per-gpu N`): FPS from train.csv
#   gpu_check.json      each step's status and seconds, the GPU, torch
#   gpu_check.log       everything printed
#
# Runs from a checkout where `make setup` was run (.venv), or with PYTHON=/path/to/python of an environment holding
# the project's requirements (the checkout is put on PYTHONPATH). It needs no network.
#   OUT=/tmp/out benchmarks/gpu_check.sh
# GPU_CHECK_DEVICE=cpu GPU_CHECK_QUICK=1: the same steps at tiny sizes on the CPU (DrQ-v2 only, batch 8, the tiny
# profile), no compile step (tests/test_gpu_check.py). GPU_CHECK_BUDGET_S: the whole script's seconds (default 470); each step gets at most
# its own limit and what is left of that budget, and a step that runs out is recorded as "timeout".
set -u -o pipefail
cd "$(dirname "$0")/.."
: "${OUT:?set OUT to the folder the JSON goes to}"
mkdir -p "$OUT"
DEVICE=${GPU_CHECK_DEVICE:-cuda}
QUICK=${GPU_CHECK_QUICK:-0}
BUDGET=${GPU_CHECK_BUDGET_S:-470}
if [ -z "${PYTHON:-}" ]; then
  if [ -x .venv/bin/python ]; then PYTHON=.venv/bin/python; else PYTHON=python3; fi
fi
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1
export MUJOCO_GL=${MUJOCO_GL:-egl} PYOPENGL_PLATFORM=${PYOPENGL_PLATFORM:-egl}
WORK=$(mktemp -d)
trap 'rm -rf "$WORK"' EXIT
LOG="$OUT/gpu_check.log"
STEPS="$WORK/steps.jsonl"
: >"$LOG"
: >"$STEPS"
START=$(date +%s)

if [ "$QUICK" = 1 ]; then
  BATCH=(--agent drqv2 --batch 8); UPD=(--warmup 0 --repeats 1)
  E2E=(--agent drqv2 --frames 40 --seed-frames 20); AMP_CHECK=(--batch 8 --updates 2 --hidden-dim 64)
  PACK_AGENT=drqv2; PACK_FRAMES=100; PACK_SET=(profile=tiny); PACK_SEED_FRAMES=80  # one 50-step episode each
else
  BATCH=(--batch 256 --batch 1024); UPD=(--warmup 3 --repeats 10)
  E2E=(--agent taco --batch 1024 --frames 6000 --seed-frames 4000); AMP_CHECK=(--batch 256 --updates 5)
  PACK_AGENT=taco; PACK_FRAMES=4000; PACK_SET=(agent.batch_size=256 replay.capacity=100000); PACK_SEED_FRAMES=1000
fi

REPRO=("$PYTHON" -m repro)

# step NAME LIMIT_S CMD...: run CMD with at most LIMIT_S (and what is left of the budget); record its outcome
step() {
  local name=$1 limit=$2; shift 2
  local left=$((BUDGET - ($(date +%s) - START)))
  [ "$left" -lt "$limit" ] && limit=$left
  if [ "$limit" -lt 10 ]; then
    echo "{\"step\": \"$name\", \"status\": \"skipped\", \"why\": \"budget spent\"}" >>"$STEPS"
    return
  fi
  echo "=== $name (limit ${limit}s): $*" | tee -a "$LOG"
  local t0 rc status
  t0=$(date +%s)
  timeout --kill-after=10 "$limit" "$@" >>"$LOG" 2>&1
  rc=$?
  case $rc in 0) status=ok ;; 124|137) status=timeout ;; *) status=failed ;; esac
  echo "{\"step\": \"$name\", \"status\": \"$status\", \"rc\": $rc, \"seconds\": $(($(date +%s) - t0))}" >>"$STEPS"
  echo "=== $name: $status (rc $rc)" | tee -a "$LOG"
}

pack_sweep() {  # pack_sweep N: write a sweep of N runs (seeds), to be run all at once on GPU 0
  local n=$1 file="$WORK/pack$1.yaml"
  {
    echo "name: pack$n"
    echo "description: gpu_check.sh packing, $n runs per GPU"
    echo "artifacts: []"
    echo "experiment: pack$n"
    echo "tasks: [cheetah_run]"
    echo "agents: [$PACK_AGENT]"
    echo "seeds: $n"
    echo "frames: $PACK_FRAMES"
    echo "eval: {every_frames: $PACK_FRAMES, episodes: null}"
    echo "common: [$(IFS=,; echo "${PACK_SET[*]}"), train.seed_frames=$PACK_SEED_FRAMES, train.eval_episodes=0,"
    echo "         train.save_frames=false, runtime.progress=false]"
    echo "variants: {base: []}"
  } >"$file"
}

# in order of what matters most, as a step that finds the budget spent is skipped: the update and loop rates, the
# CUDA graph's and the fast path's agreement, packing, then the loop timed as it trains and the compile path
step bench 150 "${REPRO[@]}" bench update --device "$DEVICE" --amp --fast "${BATCH[@]}" "${UPD[@]}" --results "$WORK/r"
step e2e 260 "${REPRO[@]}" bench e2e --device "$DEVICE" --fast "${E2E[@]}" --results "$WORK/r"
cp "$WORK"/r/bench/bench-*.json "$OUT/bench.json" 2>/dev/null
if [ "$DEVICE" = cpu ]; then
  echo '{"step": "graphs", "status": "skipped", "why": "CUDA graphs need a CUDA device"}' >>"$STEPS"
else
  step graphs 120 "$PYTHON" -m pytest -q -p no:cacheprovider tests/test_graphs.py -k cuda --junitxml "$OUT/graphs.xml"
fi
step fast_check 90 "$PYTHON" benchmarks/amp_check.py --path fast --device "$DEVICE" "${AMP_CHECK[@]}" \
  --out "$OUT/fast_check.json"
step amp_check 60 "$PYTHON" benchmarks/amp_check.py --device "$DEVICE" "${AMP_CHECK[@]}" --out "$OUT/amp_check.json"
for n in 2 4; do
  pack_sweep "$n"
  step "pack$n" $((50 + 15 * n)) "${REPRO[@]}" sweep "$WORK/pack$n.yaml" --gpus 0 --runs-per-gpu "$n" \
    --results "$WORK/pack"
done
step e2e_overlap 200 "${REPRO[@]}" bench e2e --overlap --device "$DEVICE" --fast "${E2E[@]}" --results "$WORK/r"
cp "$WORK"/r/bench/bench-*.json "$OUT/bench.json" 2>/dev/null
if [ "$QUICK" = 1 ]; then
  echo '{"step": "compile", "status": "skipped", "why": "GPU_CHECK_QUICK=1"}' >>"$STEPS"
else
  step compile 240 "${REPRO[@]}" bench update --device "$DEVICE" --compile "${BATCH[@]}" "${UPD[@]}" --results "$WORK/c"
  cp "$WORK"/c/bench/bench-*.json "$OUT/bench-compile.json" 2>/dev/null
fi

"$PYTHON" - "$WORK" "$OUT" "$DEVICE" "$PACK_SEED_FRAMES" "$(($(date +%s) - START))" <<'EOF'
import csv, json, sys
from pathlib import Path

work, out, device, seed_frames, seconds = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3], int(sys.argv[4]), int(sys.argv[5])
packing = {}
for n in (2, 4):
    runs = []
    for train in sorted((work / "pack").glob(f"pack{n}/**/train.csv")):
        with open(train) as fh:
            rows = [r for r in csv.DictReader(fh) if r.get("fps") and int(r["frame"]) > seed_frames]
        fps = [float(r["fps"]) for r in rows]
        runs.append({"run": str(train.parent.relative_to(work / "pack")), "episodes": len(fps),
                     "mean_fps": sum(fps) / len(fps) if fps else None})
    done = [r["mean_fps"] for r in runs if r["mean_fps"] is not None]
    packing[str(n)] = {"runs_per_gpu": n, "runs": runs, "fps_per_run": sum(done) / len(done) if done else None,
                       "fps_together": sum(done) if len(done) == n else None}
note = ("FPS: train.csv's fps (frames over each training episode's wall clock, evaluation excluded) of the "
        f"episodes after the {seed_frames} seed frames; fps_together: the sum over the runs sharing the GPU")
(out / "packing.json").write_text(json.dumps({"note": note, "packing": packing}, indent=2) + "\n")
info = {}
try:
    import torch
    info = {"torch": torch.__version__, "cuda": torch.cuda.is_available(),
            "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None}
except ImportError as exc:
    info = {"torch": None, "error": str(exc)}
steps = [json.loads(line) for line in (work / "steps.jsonl").read_text().splitlines() if line.strip()]
(out / "gpu_check.json").write_text(json.dumps({"device": device, "seconds": seconds, **info, "steps": steps,
                                                "files": sorted(p.name for p in out.iterdir())}, indent=2) + "\n")
print(f"gpu_check: {', '.join(s['step'] + ' ' + s['status'] for s in steps)}; {seconds} s")
EOF
