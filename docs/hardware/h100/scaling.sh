#!/usr/bin/env bash
# Device time of the seed oscillator's sweep against its size, one command-line
# run per row (scaling.txt): 200 RK4 steps per period, 20 iterations, the wall at
# 2 (impacts) or 100 (out of reach), and 2 or 60 iterations at two sizes; then
# the million-lane map (scenes/million-map.toml) end to end, twice per
# precision, the first compiling the kernels (million.txt).
# Usage, from the repository root, on a machine with the GPU:
#   B=target/release bash docs/hardware/h100/scaling.sh [OUTPUT FOLDER]
set -euo pipefail
B=${B:-target/release}
O=${1:-.}
scene=docs/hardware/h100/scale.toml
R="$O/scaling.txt"
echo "values precision wall iterations device_s lane_steps_per_s(device) bytes_per_lane chunk" | tee "$R"
one() { # count precision wall iterations
    local s
    s=$(timeout 60 $B/lyapsweep run $scene -q --backend gpu --precision $2 --set sweep.count=$1 \
        --set system.wall=$3 --set integration.iterations=$4 --out /tmp/scale 2>&1)
    local dev=$(grep -o 'timestamp queries) [0-9.]* s' <<<"$s" | grep -o '[0-9.]* s' | cut -d' ' -f1)
    local bytes=$(grep -o '[0-9]* bytes of device memory per lane' <<<"$s" | cut -d' ' -f1)
    local chunk=$(grep -o '[0-9]* RK4 steps per dispatch' <<<"$s" | cut -d' ' -f1)
    local rate=$(awk -v n=$1 -v i=$4 -v d=$dev 'BEGIN{printf "%.3e", n*5*200*i/d}')
    echo "$1 $2 $3 $4 $dev $rate $bytes $chunk" | tee -a "$R"
}
for p in f64 f32; do
  for n in 8192 16384 24576 32768 40960 49152 65536 131072 262144 524288 1048576; do
    one $n $p 2 20
  done
done
for n in 16384 32768 65536 262144; do one $n f64 100 20; done
for n in 16384 65536; do one $n f64 2 2; one $n f64 2 60; done
# A million values with longer dispatches (see docs/BENCHMARKS-GPU.md, "Steps per
# dispatch fall as lanes grow"): the budget of RK4 lane-steps per dispatch.
for budget in 268435456 1073741824; do
  echo "== LYAPSWEEP_DISPATCH_LANE_STEPS=$budget" | tee -a "$R"
  for p in f64 f32; do LYAPSWEEP_DISPATCH_LANE_STEPS=$budget one 1048576 $p 2 20; done
done
M="$O/million.txt"
TIMEFORMAT="end to end %R s"
for p in f32 f64; do
  for i in 1 2; do
    echo "== million-map $p, run $i" >>"$M"
    { time timeout 120 $B/lyapsweep run scenes/million-map.toml --backend gpu --precision $p \
        --out /tmp/million-$p || echo "exit status $?"; } >>"$M" 2>&1
  done
done
