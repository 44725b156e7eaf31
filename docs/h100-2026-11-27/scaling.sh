#!/usr/bin/env bash
# A device probe of 2026-11-27, run from .probe/ (ignored by git) with
# carry [".devbin", ".gl", ".probe"]. Its first lines were those of
# docs/device/check.sh up to its `log "commit` line (the loader, the ICD,
# the binaries unpacked into $B, $O for the outputs), left out here.
nvlib=/usr/local/nvidia/lib64
devices=$(timeout 60 $B/lyapsweep devices 2>&1)
for lib in $nvlib/libEGL_nvidia.so.0 $nvlib/libGLX_nvidia.so.0; do
    grep -q -i nvidia <<<"$devices" && break
    sed "s|\"library_path\": *\"[^\"]*\"|\"library_path\": \"$lib\"|" "$icd" >/tmp/nvidia_icd.json
    export VK_DRIVER_FILES=/tmp/nvidia_icd.json
    devices=$(timeout 60 $B/lyapsweep devices 2>&1)
done
echo "$devices" | head -2
R="$O/scaling.txt"
echo "values precision wall iterations device_s lane_steps_per_s(device) bytes_per_lane chunk" | tee "$R"
one() { # count precision wall iterations
    local s
    s=$(timeout 60 $B/lyapsweep run .probe/scale.toml -q --backend gpu --precision $2 --set sweep.count=$1 \
        --set system.wall=$3 --set integration.iterations=$4 --out /tmp/scale 2>&1)
    local dev=$(grep -o 'timestamp queries) [0-9.]* s' <<<"$s" | grep -o '[0-9.]* s' | cut -d' ' -f1)
    local bytes=$(grep -o '[0-9]* bytes of device memory per lane' <<<"$s" | cut -d' ' -f1)
    local chunk=$(grep -o '[0-9]* RK4 steps per dispatch' <<<"$s" | cut -d' ' -f1)
    local rate=$(awk -v n=$1 -v i=$4 -v d=$dev 'BEGIN{printf "%.3e", n*5*200*i/d}')
    echo "$1 $2 $3 $4 $dev $rate $bytes $chunk" | tee -a "$R"
}
for p in f64 f32; do
  for n in 8192 16384 24576 32768 40960 49152 65536 131072 262144; do one $n $p 2 20; done
done
for n in 16384 32768 65536 262144; do one $n f64 100 20; done
for n in 16384 65536; do one $n f64 2 2; one $n f64 2 60; done
