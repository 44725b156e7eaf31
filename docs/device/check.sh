#!/usr/bin/env bash
# Issue 13's hardware figures in one call of the device tool, on binaries
# built by docs/device/prepare.sh (see docs/device/README.md). Every step
# has its own time limit, so a hang costs that step, not the call; the
# outputs land in $OUT as the tool brings them back (at most 8 files).
set -uo pipefail
O=${OUT:-/tmp/device-out}
mkdir -p "$O"
log() { echo "== $(date +%T) $*" | tee -a "$O/steps.txt"; }

# The loader and libglvnd, where the machine lacks either (unpacking over a
# machine's own could break it). The H200 of 2026-11-27 had a loader but no
# libGLdispatch.so.0, which the NVIDIA ICD needs: wgpu then lists no adapter.
if ! ldconfig -p | grep -q 'libvulkan.so.1 ' || ! ldconfig -p | grep -q 'libGLdispatch.so.0 '; then
    for f in .gl/*.deb; do dpkg -x "$f" /; done
    ldconfig
fi
export WGPU_BACKEND=vulkan
icd=$(ls /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json /usr/share/vulkan/icd.d/nvidia_icd.json \
    /etc/vulkan/icd.d/nvidia_icd.json 2>/dev/null | head -1)
[ -n "$icd" ] && export VK_DRIVER_FILES=$icd
egl=/usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json
[ -f $egl ] && export __EGL_VENDOR_LIBRARY_FILENAMES=$egl
{
    echo "ICD: ${icd:-none found}"
    ldconfig -p | grep -E 'libvulkan|libGLdispatch|libGLX_nvidia|libnvidia-glcore' || true
} >"$O/loader.txt"
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
# The H200 of 2026-11-27 found the ICD's manifest, but libGLX_nvidia.so.0
# gave no vkCreateInstance: GLX wants a display. Headless, the driver's EGL
# library is its Vulkan ICD too (NVIDIA's README, "installed components"),
# so a manifest naming it comes next.
nvlib=/usr/local/nvidia/lib64
try_devices() { timeout 60 $B/lyapsweep devices 2>&1; }
devices=$(try_devices)
for lib in $nvlib/libEGL_nvidia.so.0 $nvlib/libGLX_nvidia.so.0; do
    grep -q -i nvidia <<<"$devices" && break
    [ -n "$icd" ] && [ -e "$lib" ] || continue
    echo "== ${VK_DRIVER_FILES:-default}: $devices" >>"$O/loader.txt"
    sed "s|\"library_path\": *\"[^\"]*\"|\"library_path\": \"$lib\"|" "$icd" >/tmp/nvidia_icd.json
    cat /tmp/nvidia_icd.json >>"$O/loader.txt"
    export VK_DRIVER_FILES=/tmp/nvidia_icd.json
    devices=$(try_devices)
done
echo "$devices" >>"$O/machine.txt"
if ! grep -q -i nvidia <<<"$devices"; then
    log "no NVIDIA adapter: the loader's story is in loader.txt"
    VK_LOADER_DEBUG=error,warn,driver timeout 60 $B/lyapsweep devices >>"$O/loader.txt" 2>&1
    { ls -l $nvlib /lib/libGLX_nvidia* /lib/libnvidia*; ls -l /dev/nvidia*; env | grep -i nvidia; } >>"$O/loader.txt" 2>&1
    exit 1
fi
log "adapter found with VK_DRIVER_FILES=${VK_DRIVER_FILES:-} ($(grep -o '"library_path"[^,]*' "${VK_DRIVER_FILES:-/dev/null}"))"

log "the seed's scene, twice per precision (the first compiles)"
for p in f32 f64; do
    for i in 1 2; do
        timeout 120 $B/lyapsweep run scenes/seed-fig3.toml --backend gpu --precision $p \
            --out /tmp/seed-$p >>"$O/seed.txt" 2>&1
    done
done
# A binary of an earlier commit, where prepare.sh was given one (BEFORE=path),
# runs the same scene in the same call, so that the two compare on one card.
if [ -x $B/lyapsweep-before ]; then
    log "the seed's scene with the earlier binary ($(cat .devbin/commit-before))"
    echo "== the earlier binary, $(cat .devbin/commit-before)" >>"$O/seed.txt"
    for p in f32 f64; do
        for i in 1 2; do
            timeout 120 $B/lyapsweep-before run scenes/seed-fig3.toml --backend gpu --precision $p \
                --out /tmp/seed-before-$p >>"$O/seed.txt" 2>&1
        done
    done
fi

log "the f32 sum rule against the perturbation (tests/gpu.rs's f32 scene)"
for d in 3e-5 1e-4 3e-4 1e-3; do
    echo "== f32, perturbation $d" >>"$O/seed.txt"
    timeout 60 $B/lyapsweep run docs/device/f32-perturbation.toml -q --backend gpu --precision f32 \
        --set run.validate=0 --set integration.perturbation=$d --out /tmp/f32-$d >>"$O/seed.txt" 2>&1
    cat /tmp/f32-$d/spectrum.csv >>"$O/seed.txt"
done

# lavapipe runs code that no invocation takes at full cost; a card should
# skip a branch no thread of a warp takes (docs/BENCHMARKS.md, "What
# lavapipe runs"). Into seed.txt: the tool brings back at most 8 files.
log "code no invocation runs, and the impact kernel's resolution path"
echo "== docs/lavapipe/masked-code.sh 5 2000" >>"$O/seed.txt"
BIN=$B/lyapsweep timeout 150 bash docs/lavapipe/masked-code.sh 5 2000 >>"$O/seed.txt" 2>&1

log "the bench: impacts (f32 and f64 with impacts), scaling"
timeout 240 $B/lane_steps impacts scaling >"$O/bench.txt" 2>&1

log "the GPU tests"
LYAPSWEEP_REQUIRE_GPU=1 timeout 60 $B/math64 >"$O/test-math64.txt" 2>&1
LYAPSWEEP_REQUIRE_GPU=1 timeout 150 $B/gpu >"$O/test-gpu.txt" 2>&1
LYAPSWEEP_REQUIRE_GPU=1 timeout 120 $B/gpu_models >"$O/test-gpu_models.txt" 2>&1
log "done"
