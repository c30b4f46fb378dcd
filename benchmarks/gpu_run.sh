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
#   bash benchmarks/gpu_run.sh full      there, one call of under 9 minutes (issue 38): the peer grid (both scenes,
#                                        100k-6M, 32²-1024² faces) and camera frames (1920x1080, 3840x2160) against
#                                        gsplat with the committed kernel table, each cell also with the raster and
#                                        emit kernels as A/B rows (plain, strips, emit-slot, emit-splat) and the
#                                        camera frames with gsplat's kernels by stage; the kernel table rewritten
#                                        from those A/B rows (kernel_table.json; to keep it, commit peer.csv and
#                                        camera.csv under docs/bench/ and write the table from the committed CSVs:
#                                        raster_ab_bench.py table docs/bench/raster_ab_lavapipe.csv
#                                        docs/bench/emit_ab_lavapipe.csv docs/bench/<peer>.csv docs/bench/<camera>.csv;
#                                        tests/test_kernel_table.py checks it is theirs); the chart; the LOD probe.
#                                        Into $OUT: peer.csv,
#                                        camera.csv, kernel_table.json, performance.png, lod.csv, full.log
#                                        (and gsplat_cuda.so.xz). Steps end at deadlines, so the call ends in time
#                                        with what they measured; carry .gl and .whl (prepare makes them)
#   bash benchmarks/gpu_run.sh final     there, one call of under 8 minutes (issue 36, items 4-5): the final frame's
#                                        fidelity (fidelity_bench.py: our F12 camera path against gsplat classic, eight
#                                        1920x1080 views of the guitar and the sample room, the worst view's differing
#                                        splats; the numpy stand-in checked against gsplat at 320x180) and its cost
#                                        (frame_cost_bench.py: a 1080p frame with and without a depth cut, per stage,
#                                        beside gsplat; room, guitar, random and shell at 1M and 3M), the chart. Into
#                                        $OUT: fidelity.csv, fidelity_worst.csv, fidelity_splats.csv,
#                                        fidelity_<capture>_worst.png, frame_cost.csv, final-frame-cost.png, final.log
#                                        (and gsplat_cuda.so.xz). Steps end at deadlines; carry .gl and .whl
#   bash benchmarks/gpu_run.sh refs      there, one call of under 6 minutes (issue 36, items 1 and 5): gsplat 1.5.3
#                                        classic's reference images for native_frame_bench.py (fidelity_bench's eight
#                                        views of the guitar and the sample room at 480x270, float16, ours beside
#                                        them) and at 1920x1080 our time per frame (GPU, wall) and gsplat's, our PSNR.
#                                        Into $OUT: refs_guitar.npz, refs_room.npz, refs_guitar.png, refs_room.png,
#                                        refs.csv, refs.log (and gsplat_cuda.so.xz); they belong in
#                                        docs/bench/native_frame_refs/. Carry .gl and .whl
#   bash benchmarks/gpu_run.sh stages    there, one call of about a minute (issue 38, a bake's wall beside its GPU
#                                        time): auto_bake_core.py --stages in two processes (per stage wall, GPU,
#                                        the first with --ab: before/after the issue's host work, alternating;
#                                        host = wall - GPU and submissions of the sample's default bake, Lighting
#                                        Auto's bake of the sphere and a 1920x1080 camera frame, every recording
#                                        timestamped; and a new process's context, upload and first bakes, the
#                                        second process finding the first's pipeline cache on disk); then the
#                                        Auto and Volume bakes of native_bench's sphere (its GPU series). Into $OUT:
#                                        bake_stages.csv, auto_bake_core.csv, volume_bake_core.csv, stages.log.
#                                        Carry .gl and .whl
#   bash benchmarks/gpu_run.sh profile   there, about a minute (issues 37 and 38: where host time goes):
#                                        host_profile.py, cProfile of the default bake, Lighting Auto's bake, a
#                                        1080p camera frame and Lighting Volume's bake of three meshes. Into $OUT:
#                                        profile.log and one .pstats per work; then the camera frame's wall
#                                        by host copy threads (--copy-ab) into the log. Carry .gl and .whl
#   AB=v1,v2 [TRIALS=out/trials] bash benchmarks/gpu_run.sh ab
#                                        there, ~3 minutes (issue 38): peer_bench's A/B rows of those VARIANTS
#                                        (e.g. sh-splat: the SH uploaded splat-major) beside ours and gsplat, 1M and
#                                        6M, faces 64² and 1024², camera frames 1920x1080 and 3840x2160, gsplat's
#                                        kernels by stage at the camera sizes; the LOD probe (lod_bench, 1M at 32²).
#                                        Into $OUT: peer.csv, camera.csv, lod.csv, ab.log. Carry .gl and .whl
#   bash benchmarks/gpu_run.sh grow      there, about a minute (issue 37): volume_grow_bench.py (the light volume
#                                        grown over a dragged mesh against baked whole). Into $OUT: volume_grow.csv,
#                                        volume_grow.png, grow.log. Carry .gl and .whl
#   bash benchmarks/gpu_run.sh volume    there, one call of about a minute (issue 37): volume_bench.py (the light
#                                        volume's accuracy against per-point probes at the five places, its bake's
#                                        cost against a World-only bake, and with host-made maps: GPU_MAPS A/B),
#                                        after tests/test_gpu_volume_maps.py (the GPU maps against numpy's, on
#                                        the device; its line "passed" in volume.log). Into $OUT: volume_accuracy.csv,
#                                        volume_cost.csv, volume_bench.png, volume.log. Carry .gl and .whl
#                                        VOLUME_POINTS=32 (default 256, volume_bench's): shading points per
#                                        sphere; compare rows with lavapipe's only at the same count (the CSV's
#                                        points column)
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
  # the probe's files (core/image_io.py: auto_bake_core.py's bakes write them, as a user's bake does)
  python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 --implementation cp \
    --platform manylinux_2_28_x86_64 -d .whl "$(grep -i '^openimageio==' requirements.txt)"
  python3 benchmarks/kernel_trials.py build
  echo "[gpu_run] carry: .gl .whl out/trials"
  ;;
trials|grid|full|final|refs|stages|volume|profile|ab|grow)
  t_start=$SECONDS
  for f in .gl/*.deb; do dpkg -x "$f" /; done
  ldconfig
  icd=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json  # device/README: where the loader may not look
  if [ -z "${VK_DRIVER_FILES:-}" ] && [ -e "$icd" ] && ! ls /etc/vulkan/icd.d/*.json /usr/share/vulkan/icd.d/*.json \
      >/dev/null 2>&1; then
    export VK_DRIVER_FILES=$icd __EGL_VENDOR_LIBRARY_FILENAMES=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
  fi
  python3 -m pip install -q --no-index --no-deps --target /tmp/site .whl/*.whl
  export PYTHONPATH=/tmp/site:$PWD GS_IBL_DEVICE=gpu TORCH_CUDA_ARCH_LIST=9.0 MAX_JOBS=16 \
    TORCH_EXTENSIONS_DIR=/tmp/torch_extensions
  if [ -f .whl/gsplat_cuda.so.xz ]; then
    xz -dc .whl/gsplat_cuda.so.xz > /tmp/gsplat_cuda.so
    export GSPLAT_SO=/tmp/gsplat_cuda.so
  fi
  out=${OUT:-out/bench}
  nvidia-smi --query-gpu=name,driver_version,clocks.max.sm --format=csv,noheader
  export PYTHONUNBUFFERED=1
  mkdir -p "$out"
  if [ "$1" = full ]; then
    # Deadlines (seconds): the peer run takes no new configuration after 320 s of its own (gsplat's ~55 s compile
    # included; ~250 s expected) and is stopped at 370; the LOD probe gets 90; set-up and the rest ~40: the call
    # ends within 9 minutes (about 6 expected).
    log="$out/full.log"
    (
      set +e
      timeout --signal=INT --kill-after=10 370 python3 benchmarks/peer_bench.py bench --scenes shell,random \
        --counts 6000000,1000000,100000 --faces 32,64,128,256,512,1024 --cameras 1920x1080,3840x2160 \
        --ab plain,strips,emit-slot,emit-splat --gsplat-stages cameras --warmup 0.3 --rounds 3 --block 5 \
        --deadline 320 --csv "$out/peer.csv" --camera-csv "$out/camera.csv" || echo "[gpu_run] peer_bench: exit $?"
      python3 benchmarks/raster_ab_bench.py table "$out/peer.csv" "$out/camera.csv" \
        --merge gs_ibl_addon/core/render/kernel_table.json --out "$out/kernel_table.json" \
        || echo "[gpu_run] kernel table: exit $?"
      python3 benchmarks/peer_bench.py plot --csv "$out/peer.csv" --png "$out/performance.png" \
        || echo "[gpu_run] plot: exit $?"
      timeout --signal=INT --kill-after=10 90 python3 benchmarks/lod_bench.py --counts 1000000 --faces 32 --ks 4 \
        --hold-clock --skip-accuracy --csv "$out/lod.csv" || echo "[gpu_run] lod_bench: exit $?"
      echo "[gpu_run] full: $((SECONDS - t_start)) s"
    ) 2>&1 | tee "$log"
  elif [ "$1" = final ]; then
    # Deadlines (seconds): fidelity takes no new capture after 180 s of its own (gsplat's ~55 s compile included;
    # ~100 s expected) and is stopped at 210; the frame cost takes no new scene after 130 s (~80 expected) and is
    # stopped at 160; with set-up (~30 s) and the chart the call ends within about 7 minutes (about 4 expected).
    log="$out/final.log"
    (
      set +e
      timeout --signal=INT --kill-after=10 210 python3 benchmarks/fidelity_bench.py --captures guitar,room \
        --peer gsplat --size 1920x1080 --check-port 320x180 --deadline 180 --csv "$out/fidelity.csv" \
        --worst-csv "$out/fidelity_worst.csv" --splats-csv "$out/fidelity_splats.csv" --png-dir "$out" \
        || echo "[gpu_run] fidelity_bench: exit $?"
      timeout --signal=INT --kill-after=10 160 python3 benchmarks/frame_cost_bench.py bench \
        --scenes room,guitar,random:1M,shell:1M,random:3M,shell:3M --size 1920x1080 --gsplat-stages \
        --warmup 0.5 --rounds 3 --block 5 --deadline 130 --csv "$out/frame_cost.csv" \
        || echo "[gpu_run] frame_cost_bench: exit $?"
      python3 benchmarks/frame_cost_bench.py plot --csv "$out/frame_cost.csv" --png "$out/final-frame-cost.png" \
        || echo "[gpu_run] plot: exit $?"
      echo "[gpu_run] final: $((SECONDS - t_start)) s"
    ) 2>&1 | tee "$log"
  elif [ "$1" = stages ]; then
    # Two processes: the first makes every pipeline with an empty disk cache, the second finds it (the "new
    # process" rows); each then times its warm bakes and frame. Deadlines: 150 s and 90 s; about a minute expected.
    log="$out/stages.log"
    (
      set +e
      export GS_IBL_CACHE_DIR=/tmp/gs-ibl-cache
      rm -rf "$GS_IBL_CACHE_DIR"
      timeout --signal=INT --kill-after=10 150 python3 benchmarks/auto_bake_core.py --stages --ab --repeats 10 \
        --out "$out/bake_stages.csv" || echo "[gpu_run] auto_bake_core --stages: exit $?"
      timeout --signal=INT --kill-after=10 90 python3 benchmarks/auto_bake_core.py --stages --repeats 3 \
        --out "$out/bake_stages.csv" || echo "[gpu_run] auto_bake_core --stages (cache on disk): exit $?"
      # native_bench's GPU series: Lighting Auto's and Lighting Volume's bakes of its sphere (core, clock held)
      timeout --signal=INT --kill-after=10 120 python3 benchmarks/auto_bake_core.py --repeats 5 \
        --out "$out/auto_bake_core.csv" --volume-out "$out/volume_bake_core.csv" \
        || echo "[gpu_run] auto_bake_core: exit $?"
      echo "[gpu_run] stages: $((SECONDS - t_start)) s"
    ) 2>&1 | tee "$log"
  elif [ "$1" = volume ]; then
    # The light volume (issue 37): accuracy against per-point probes and the bake's cost against a World-only bake.
    # Deadline 400 s; about a minute expected.
    log="$out/volume.log"
    (
      set +e
      # the GPU-made maps against their numpy reference on this device (volume_bake.GPU_MAPS; a few seconds)
      timeout 60 python3 -m pytest -q -p no:cacheprovider tests/test_gpu_volume_maps.py \
        || echo "[gpu_run] test_gpu_volume_maps: exit $?"
      timeout --signal=INT --kill-after=10 400 python3 benchmarks/volume_bench.py --points "${VOLUME_POINTS:-256}" --repeats 3 \
        --out-csv "$out/volume.csv" --png "$out/volume_bench.png" || echo "[gpu_run] volume_bench: exit $?"
      echo "[gpu_run] volume: $((SECONDS - t_start)) s"
    ) 2>&1 | tee "$log"
  elif [ "$1" = grow ]; then
    # The light volume grown over a dragged mesh against baked whole (issue 37): about a minute
    log="$out/grow.log"
    (
      set +e
      timeout --signal=INT --kill-after=10 300 python3 benchmarks/volume_grow_bench.py --csv "$out/volume_grow.csv" \
        --png "$out/volume_grow.png" || echo "[gpu_run] volume_grow_bench: exit $?"
      echo "[gpu_run] grow: $((SECONDS - t_start)) s"
    ) 2>&1 | tee "$log"
  elif [ "$1" = profile ]; then
    log="$out/profile.log"
    (
      set +e
      timeout --signal=INT --kill-after=10 240 python3 benchmarks/host_profile.py --repeats 5 --top 30 --out "$out" \
        || echo "[gpu_run] host_profile: exit $?"
      timeout --signal=INT --kill-after=10 60 python3 benchmarks/host_profile.py --copy-ab --repeats 30 \
        || echo "[gpu_run] host_profile --copy-ab: exit $?"
      echo "[gpu_run] profile: $((SECONDS - t_start)) s"
    ) 2>&1 | tee "$log"
  elif [ "$1" = refs ]; then
    # Deadline: gsplat's ~55 s compile, then ~2 s a view; stopped at 300 s
    log="$out/refs.log"
    (
      set +e
      timeout --signal=INT --kill-after=10 300 python3 benchmarks/native_frame_bench.py refs --captures guitar,room \
        --peer gsplat --size 480x270 --out "$out" || echo "[gpu_run] native_frame_bench refs: exit $?"
      echo "[gpu_run] refs: $((SECONDS - t_start)) s"
    ) 2>&1 | tee "$log"
  elif [ "$1" = ab ]; then
    # AB=variant[,variant] (peer_bench VARIANTS): those rows beside ours and gsplat at 1M and 6M, cube faces 64² and
    # 1024², camera frames 1920x1080 and 3840x2160, gsplat's kernels by stage at the camera sizes; ~3 minutes
    log="$out/ab.log"
    (
      set +e
      timeout --signal=INT --kill-after=10 420 python3 benchmarks/peer_bench.py bench --scenes shell,random \
        --counts 6000000,1000000 --faces 64,1024 --cameras 1920x1080,3840x2160 --ab "${AB:?AB=variants}" ${TRIALS:+--trials "$TRIALS"} \
        --gsplat-stages cameras --warmup 0.3 --rounds 3 --block 5 --deadline 360 --csv "$out/peer.csv" \
        --camera-csv "$out/camera.csv" || echo "[gpu_run] peer_bench: exit $?"
      timeout --signal=INT --kill-after=10 90 python3 benchmarks/lod_bench.py --counts 1000000 --faces 32 --ks 4 \
        --hold-clock --skip-accuracy --csv "$out/lod.csv" || echo "[gpu_run] lod_bench: exit $?"
      echo "[gpu_run] ab: $((SECONDS - t_start)) s"
    ) 2>&1 | tee "$log"
  elif [ "$1" = trials ]; then
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
    # find exits non-zero on unreadable places (/proc): under set -e and pipefail that ended the script here
    so=$(find "$TORCH_EXTENSIONS_DIR" / -name "gsplat_cuda*.so" -path "*torch_extensions*" 2>/dev/null | head -1) || true
    [ -n "$so" ] && xz -1 -c "$so" > "$out/gsplat_cuda.so.xz"
  fi
  ;;
*)
  echo "usage: bash benchmarks/gpu_run.sh prepare|trials|grid|full|final|refs|stages|volume|profile|ab|grow" >&2
  exit 2
  ;;
esac
