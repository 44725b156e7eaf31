#!/usr/bin/env bash
# Issue 13's hardware figures in one call of the device tool, on binaries
# built by docs/device/prepare.sh (see docs/device/README.md). Every step
# has its own time limit, so a hang costs that step, not the call; the
# outputs land in $OUT as the tool brings them back (at most 8 files).
set -uo pipefail
O=${OUT:-/tmp/device-out}
mkdir -p "$O"
log() { echo "== $(date +%T) $*" | tee -a "$O/steps.txt"; }

# The loader and libglvnd, where the machine lacks them (unpacking over a
# machine's own could break it).
if ! ldconfig -p | grep -q 'libvulkan.so.1 '; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
export WGPU_BACKEND=vulkan
if [ -f /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json ]; then
    export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
fi
B=/tmp/devbin
mkdir -p $B
for f in .devbin/*.xz; do xz -dc "$f" >"$B/$(basename "$f" .xz)"; done
chmod +x $B/*
# The tests read the committed models and scenes by the path they were
# built at.
built_at=/work/main
[ -e $built_at ] || { mkdir -p "$(dirname $built_at)" && ln -s "$PWD" $built_at; }

log "commit $(cat .devbin/commit)"
{ nvidia-smi; nvidia-smi -q -d CLOCK; } >"$O/machine.txt" 2>&1
timeout 60 $B/lyapsweep devices >>"$O/machine.txt" 2>&1

log "the seed's scene, twice per precision (the first compiles)"
for p in f32 f64; do
    for i in 1 2; do
        timeout 120 $B/lyapsweep run scenes/seed-fig3.toml --backend gpu --precision $p \
            --out /tmp/seed-$p >>"$O/seed.txt" 2>&1
    done
done

log "the bench: impacts (f32 and f64 with impacts), scaling"
timeout 240 $B/lane_steps impacts scaling >"$O/bench.txt" 2>&1

log "the GPU tests"
LYAPSWEEP_REQUIRE_GPU=1 timeout 150 $B/gpu >"$O/test-gpu.txt" 2>&1
LYAPSWEEP_REQUIRE_GPU=1 timeout 120 $B/gpu_models >"$O/test-gpu_models.txt" 2>&1
log "done"
