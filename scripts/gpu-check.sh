#!/usr/bin/env bash
# The GPU measurements of one short lease on a CUDA machine, as one script: is the GPU there,
# do the GPU backends agree with `cpu`, how fast is a gradient step on it (`bench train`), and
# how many steps per second does a real `mdrlat train` run make. Everything it measures goes
# to $OUT (default out/gpu): gpu-check.log (the whole transcript), bench-*.jsonl, the short
# agreement runs' metrics.csv and the long run's metrics.csv, eval.csv and progress.csv.
#
#   MDRLAT_TCH_BIN=target-tch/release/mdrlat MDRLAT_WGPU_BIN=target-wgpu/release/mdrlat \
#     LONG_SECONDS=240 bash scripts/gpu-check.sh
#
# With MDRLAT_TCH_BASE=<an earlier tch binary>, it also measures that one beside this one, in
# the same lease: MDRLAT's `bench train` alternately (base-bench-*.jsonl beside
# side-bench-*.jsonl), `--profile` of each, and a real run of LONG_SECONDS each
# (base-progress.csv beside progress.csv). Keep LONG_SECONDS near 100 then: the runs double.
#
# `--device tch-cuda` needs a binary built with `--features tch` against the LibTorch of the
# machine's own PyTorch, same version, with libtorch_cuda in the folder it was linked against
# (burn-tch decides at build time whether a binary may use a GPU): on a machine without CUDA,
# `MDRLAT_TORCH_VERSION=2.11.0 MDRLAT_TCH_CUDA=link bash scripts/setup-tch.sh` builds one.
# It runs here with that PyTorch's lib folder on LD_LIBRARY_PATH.
# `--device wgpu` needs a binary built with `--features wgpu` and a Vulkan loader.
# Each stage has its own time limit and a failed stage does not stop the next.
set -uo pipefail
# Paths given relative to where the script was started from, before moving to the root.
absolute() { if [ -n "$1" ]; then realpath -m "$1"; fi; }
TCH=$(absolute "${MDRLAT_TCH_BIN:-}")
BASE=$(absolute "${MDRLAT_TCH_BASE:-}")
WGPU=$(absolute "${MDRLAT_WGPU_BIN:-}")
OUT=$(absolute "${OUT:-}")
cd "$(dirname "$0")/.."
TCH=${TCH:-target-tch/release/mdrlat}
OUT=${OUT:-out/gpu}
LONG_SECONDS=${LONG_SECONDS:-240}
LONG_VARIANT=${LONG_VARIANT:-mdrlat}
BENCH_SECONDS=${BENCH_SECONDS:-2}
RUNS=${RUNS:-$(mktemp -d)}
mkdir -p "$OUT"
exec > >(tee -a "$OUT/gpu-check.log") 2>&1
TEE=$!

stage() { echo; echo "== $(date -u +%H:%M:%S) $*"; }

stage "machine"
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv 2>&1
lscpu | grep -E "Model name|^CPU\(s\)" || true

# LibTorch: the machine's PyTorch's own libraries.
TORCH_LIB=${MDRLAT_TORCH_LIB:-$(python3 -c 'import os, torch; print(os.path.join(os.path.dirname(torch.__file__), "lib")); ' 2>/dev/null)}
python3 -c 'import torch; print("torch", torch.__version__, "cuda", torch.version.cuda)' 2>&1 || true
if [ -z "$TORCH_LIB" ] || [ ! -d "$TORCH_LIB" ]; then
  echo "no LibTorch: python3 cannot import torch and MDRLAT_TORCH_LIB is unset; skipping tch-cuda"
  TCH=""
fi
TCH_ENV=(env "LD_LIBRARY_PATH=$TORCH_LIB${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
  "GLIBC_TUNABLES=glibc.malloc.mmap_threshold=33554432:glibc.malloc.trim_threshold=17179869184")
TCH_RUN=("${TCH_ENV[@]}" "$TCH")
BASE_RUN=("${TCH_ENV[@]}" "$BASE")

# A real training run of LONG_SECONDS (paper settings) with a binary wrapper; its metrics
# go to $OUT/<label>long-metrics.csv and long-eval.csv, the step it had reached every 10 s to
# $OUT/<label>progress.csv.
long_run() { # label binary-wrapper...
  local label=$1 run="$RUNS/${1}long" step
  shift
  # A background job of a script ignores SIGINT, and `mdrlat train` has no handler: TERM,
  # through `timeout` (which passes it on), with a bound in case this loop is cut short.
  timeout -s TERM $((LONG_SECONDS + 60)) "$@" train --device tch-cuda \
    --variant "$LONG_VARIANT" --seed 0 --out "$run" &
  local pid=$! start
  echo "unix_s,step" >"$OUT/${label}progress.csv"
  start=$(date +%s)
  while kill -0 "$pid" 2>/dev/null && [ $(($(date +%s) - start)) -lt "$LONG_SECONDS" ]; do
    sleep 10
    step=$(tail -n +2 "$run/metrics.csv" 2>/dev/null | tail -n 1 | cut -d, -f1)
    echo "$(date +%s.%N),${step:-0}" | tee -a "$OUT/${label}progress.csv"
  done
  kill -TERM "$pid" 2>/dev/null
  wait "$pid"
  [ -f "$run/metrics.csv" ] && cp "$run/metrics.csv" "$OUT/${label}long-metrics.csv"
  # Only with an evaluation in it (the device tool brings back a limited number of files).
  if [ -f "$run/eval.csv" ] && [ "$(wc -l <"$run/eval.csv")" -gt 1 ]; then
    cp "$run/eval.csv" "$OUT/${label}long-eval.csv"
  fi
}

# Same seed, same 400 steps (300 gradient steps), on cpu and on the GPU: the losses of
# metrics.csv side by side (LibTorch's cuDNN convolutions may use TF32, so not bit-equal).
agree() { # device label binary-wrapper...
  local device=$1 label=$2
  shift 2
  timeout 120 "$@" train --variant mdrlat --steps 400 --seed 3 --device "$device" \
    --set train.learning_starts=100 --set train.eval_interval=400 --set train.eval_episodes=2 \
    --out "$RUNS/agree-$label" && cp "$RUNS/agree-$label/metrics.csv" "$OUT/agree-$label.csv"
}

if [ -n "$TCH" ] && [ -x "$TCH" ]; then
  stage "tch-cuda: smoke"
  if timeout 60 "${TCH_RUN[@]}" bench train --device tch-cuda --variants laser-only --seconds 0.2; then
    stage "agreement: cpu and tch-cuda, 400-step MDRLAT runs"
    agree cpu cpu "${TCH_RUN[@]}"
    agree tch-cuda tch-cuda "${TCH_RUN[@]}"
    paste -d'|' "$OUT/agree-cpu.csv" "$OUT/agree-tch-cuda.csv" 2>/dev/null | tail -3

    stage "tch-cuda: bench train, all variants, batch 32"
    timeout 200 "${TCH_RUN[@]}" bench train --device tch-cuda --json --seconds "$BENCH_SECONDS" |
      tee "$OUT/bench-tch-cuda.jsonl"
    stage "tch-cuda: where an MDRLAT step goes; batch 128 and 512"
    timeout 60 "${TCH_RUN[@]}" bench train --device tch-cuda --variants mdrlat --profile --seconds 1
    for b in 128 512; do
      timeout 40 "${TCH_RUN[@]}" bench train --device tch-cuda --variants mdrlat --batch "$b" --seconds 1 --json |
        grep '"bench":"train"' | tee -a "$OUT/bench-tch-cuda.jsonl"
    done

    if [ -n "$BASE" ] && [ -x "$BASE" ]; then
      stage "side by side: MDRLAT bench train, the base binary ($BASE) and this one, twice"
      for round in 1 2; do
        timeout 60 "${BASE_RUN[@]}" bench train --device tch-cuda --variants mdrlat --seconds 2 --json |
          grep '"bench":"train"' | tee -a "$OUT/base-bench-tch-cuda.jsonl"
        timeout 60 "${TCH_RUN[@]}" bench train --device tch-cuda --variants mdrlat --seconds 2 --json |
          grep '"bench":"train"' | tee -a "$OUT/side-bench-tch-cuda.jsonl"
      done
      stage "the base binary: where an MDRLAT step goes"
      timeout 60 "${BASE_RUN[@]}" bench train --device tch-cuda --variants mdrlat --profile --seconds 1
      stage "the base binary: a real $LONG_VARIANT run for ${LONG_SECONDS}s (paper settings)"
      long_run base- "${BASE_RUN[@]}"
    fi
    stage "tch-cuda: a real $LONG_VARIANT run for ${LONG_SECONDS}s (paper settings)"
    long_run "" "${TCH_RUN[@]}"

    # Where the GPU's time goes, where Nsight Systems is installed.
    if command -v nsys >/dev/null; then
      stage "nsys: CUDA kernels and transfers of a 1 s MDRLAT bench"
      timeout 120 nsys profile --stats=false -o "$RUNS/nsys" --force-overwrite true \
        "${TCH_RUN[@]}" bench train --device tch-cuda --variants mdrlat --seconds 1 >/dev/null &&
        timeout 60 nsys stats --report cuda_gpu_kern_sum,cuda_gpu_mem_time_sum,cuda_api_sum \
          "$RUNS/nsys.nsys-rep" 2>&1 | head -80
    else
      stage "no nsys here ($(command -v ncu nvprof 2>/dev/null | tr '\n' ' '))"
    fi
  else
    stage "tch-cuda failed to start: what the binary links"
    LD_LIBRARY_PATH="$TORCH_LIB" ldd "$TCH" | grep -E "not found|torch|c10" || true
  fi
fi

if [ -n "$WGPU" ] && [ -x "$WGPU" ]; then
  stage "wgpu: Vulkan devices"
  ls /usr/share/vulkan/icd.d /etc/vulkan/icd.d /usr/local/nvidia/share/vulkan/icd.d 2>&1 || true
  stage "wgpu: bench train, laser-only and MDRLAT, batch 32"
  timeout 150 "$WGPU" bench train --device wgpu --variants laser-only,mdrlat --json --seconds 1 |
    tee "$OUT/bench-wgpu.jsonl"
fi
stage "done"
# Let tee write the last lines before $OUT is collected.
exec 1>&- 2>&-
wait "$TEE"
