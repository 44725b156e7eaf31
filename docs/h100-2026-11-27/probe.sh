#!/usr/bin/env bash
# A device probe of 2026-11-27, run from .probe/ (ignored by git) with
# carry [".devbin", ".gl", ".probe"]. Its first lines were those of
# docs/device/check.sh up to its `log "commit` line (the loader, the ICD,
# the binaries unpacked into $B, $O for the outputs), left out here.
for f in .probe/*.xz; do xz -dc "$f" >"$B/$(basename "$f" .xz)"; done
chmod +x $B/*
nvlib=/usr/local/nvidia/lib64
devices=$(timeout 60 $B/lyapsweep devices 2>&1)
for lib in $nvlib/libEGL_nvidia.so.0 $nvlib/libGLX_nvidia.so.0; do
    grep -q -i nvidia <<<"$devices" && break
    sed "s|\"library_path\": *\"[^\"]*\"|\"library_path\": \"$lib\"|" "$icd" >/tmp/nvidia_icd.json
    export VK_DRIVER_FILES=/tmp/nvidia_icd.json
    devices=$(timeout 60 $B/lyapsweep devices 2>&1)
done
echo "$devices"
timeout 60 $B/probe_f32 2>&1 | tee "$O/probe.txt"
timeout 60 $B/probe_f64 2>&1 | tee -a "$O/probe.txt"
