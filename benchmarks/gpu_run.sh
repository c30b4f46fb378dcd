#!/usr/bin/env bash
# The GPU machine's runs, in as few device calls as they can take (it has no registry and no glslc).
#   bash benchmarks/gpu_run.sh prepare   here: the Vulkan loader debs (.gl), the wheels (.whl), the kernel trials
#                                        (out/trials); then carry .gl, .whl and out/trials
#   bash benchmarks/gpu_run.sh trials    there: shader statistics and peer_bench at 1024² for every trial, the
#                                        strip kernels and the per-splat emit (--ab strips,emit-splat: CPU devices'
#                                        defaults), beside the committed kernels and gsplat in one process; CSVs into $OUT
#   bash benchmarks/gpu_run.sh grid      there: the whole peer grid (100k-6M, 64²-1024², both scenes) with the
#                                        strip kernels as A/B rows, docs/performance.png's chart, and the LOD probe
#                                        (lod_bench, 1M at 32²); CSVs and PNGs into $OUT
# gsplat JIT-compiles its CUDA on first use (~55 s); its build comes back as $OUT/gsplat_cuda.so.xz: put it in .whl
# and the next run loads it (GSPLAT_SO). shared/NOTES-vulkan-and-gpu.md says why each package is there.
set -euo pipefail
cd "$(dirname "$0")/.."
case "${1:-}" in
prepare)
  mkdir -p .gl .whl /tmp/amd64/partial
  grep -qx "/.gl/" .git/info/exclude 2>/dev/null || echo /.gl/ >> .git/info/exclude
  grep -qx "/.whl/" .git/info/exclude 2>/dev/null || echo /.whl/ >> .git/info/exclude
  o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64)
  apt-get "${o[@]}" update >/dev/null
  (cd .gl && apt-get "${o[@]}" download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 libglx0 libgles2)
  # gsplat imports rich (not on the GPU machine; jaxtyping, ninja and torch are there: device/KINDS.md)
  python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 -d .whl \
    cffi==2.0.0 pycparser vulkan==1.3.275.1 plyfile gsplat==1.5.3 rich markdown-it-py mdurl pygments
  python3 benchmarks/kernel_trials.py build
  echo "[gpu_run] carry: .gl .whl out/trials"
  ;;
trials|grid)
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .whl/*.whl
  export PYTHONPATH=/tmp/site:$PWD GS_IBL_DEVICE=gpu TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=16
  if [ -f .whl/gsplat_cuda.so.xz ]; then
    xz -dc .whl/gsplat_cuda.so.xz > /tmp/gsplat_cuda.so
    export GSPLAT_SO=/tmp/gsplat_cuda.so
  fi
  out=${OUT:-out/bench}
  nvidia-smi --query-gpu=name,driver_version,clocks.max.sm --format=csv,noheader
  if [ "$1" = trials ]; then
    python3 benchmarks/shader_stats.py --kernels gs_raster,gs_raster_conic,gs_raster_strips,gs_raster_conic_strips \
      --trials out/trials --csv "$out/trial_stats.csv" | grep -E "Register|Shared Memory|Spill" || true
    python3 benchmarks/peer_bench.py bench --scenes random,shell --counts 1000000,6000000 --faces 1024 \
      --ab strips,emit-splat --trials out/trials --csv "$out/trials.csv" --png "$out/trials.png"
  else
    python3 benchmarks/peer_bench.py bench --scenes random,shell --counts 100000,1000000,6000000 \
      --faces 64,128,256,1024 --ab strips --csv "$out/peer.csv"
    python3 benchmarks/peer_bench.py plot --csv "$out/peer.csv" --png "$out/performance.png"
    python3 benchmarks/lod_bench.py --counts 1000000 --faces 32 --ks 4 --hold-clock --skip-accuracy \
      --csv "$out/lod.csv"
  fi
  if [ -z "${GSPLAT_SO:-}" ]; then
    so=$(find / -name "gsplat_cuda*.so" -path "*torch_extensions*" 2>/dev/null | head -1)
    [ -n "$so" ] && xz -1 -c "$so" > "$out/gsplat_cuda.so.xz"
  fi
  ;;
*)
  echo "usage: bash benchmarks/gpu_run.sh prepare|trials|grid" >&2
  exit 2
  ;;
esac
