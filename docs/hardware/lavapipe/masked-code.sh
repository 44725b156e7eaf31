#!/bin/bash
# Does lavapipe pay for kernel code that no invocation runs?
#
# 1. Four builds of the integrate kernel without impact code, run on the
# 200-step sweep with the wall out of reach (4096 values, 200 steps per
# period, transient 20, iterations 20, f64), interleaved, median device time:
#   base     the kernel as it is
#   never    plus LINES lines of arithmetic per invocation, under an `if`
#            whose condition is false for every invocation (a uniform zero)
#   no-trip  the same lines in a loop of zero passes
#   always   the same lines run by every invocation (the result kept)
# If masked-off code were skipped, `never` and `no-trip` would cost what
# `base` costs.
# 2. Three builds of the impact kernel on the same sweep with the wall at 2:
#   impacts      the kernel as it is
#   unentered    the step loop's tests guarded by a uniform zero: no step
#                leaves the loop, the resolution path is compiled in but
#                never entered (the orbits pass through the wall: the
#                numbers are wrong, the time is the kernel's shape)
#   unresolved   the same without the resolution path
#   no-wall      the kernel without impact code (wall at 100), for scale
# docs/BENCHMARKS-GPU.md ("What lavapipe runs") has the figures.
#
# Usage, from the repository root, after `cargo build --release` (or with
# BIN naming another build of lyapsweep):
#   bash docs/hardware/lavapipe/masked-code.sh [runs (default 9)] [lines (default 2000)]
# On a hardware GPU the same builds show what a GPU does with code no
# thread of a warp takes.
set -euo pipefail
runs=${1:-9}
lines=${2:-2000}
bin=${BIN:-target/release/lyapsweep}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

cat >"$work/scene.toml" <<TOML
name = "masked-code"
[system]
kind = "impact-oscillator"
wall = WALL
[sweep]
from = 0.5
to = 1.5
count = 4096
[integration]
steps_per_period = 200
transient = 20
iterations = 20
[run]
backend = "gpu"
precision = "f64"
validate = 0
TOML
sed s/WALL/100.0/ "$work/scene.toml" >"$work/no-wall.toml"
sed s/WALL/2.0/ "$work/scene.toml" >"$work/wall.toml"

# A chain of dependent multiply-adds that stays finite.
chain="var q = y[0];"
for ((i = 0; i < lines; i++)); do chain+=" q = q * real(0.5) + real($i.25);"; done
anchor='    for (var k = c.x; k < end; k = k + 1u) {'
# variant NAME FROM TO ...: shaders/ with integrate.wgsl's text FROM
# replaced by TO (each exactly once), under $work/NAME. Plain bash: the
# GPU machines may lack python.
variant() {
    local name=$1 file text old new rest
    shift
    mkdir -p "$work/$name"
    cp -r shaders/. "$work/$name"
    file="$work/$name/integrate.wgsl"
    text=$(<"$file")
    while (($#)); do
        old=$1 new=$2
        shift 2
        rest=${text#*"$old"}
        if [[ $rest == "$text" || $rest == *"$old"* ]]; then
            echo "integrate.wgsl changed: not once: $old" >&2
            exit 1
        fi
        text=${text/"$old"/"$new"}
    done
    printf '%s\n' "$text" >"$file"
}
variant base
variant never "$anchor" "    if (control.opaque_zero != 0u) { $chain y[0] = q; }
$anchor"
variant no-trip "$anchor" "    for (var i = 0u; i < control.opaque_zero; i = i + 1u) { $chain y[0] = q; }
$anchor"
variant always "$anchor" "    { $chain y[0] = select(y[0], q, control.opaque_zero != 0u); }
$anchor"

rest='            if (resting_on(walls, y) < WALLS) {'
meets='            if (reaches_a_stop(walls, y, h, y1)) {'
never_rests='            if (control.opaque_zero != 0u && resting_on(walls, y) < WALLS) {'
never_meets='            if (control.opaque_zero != 0u && reaches_a_stop(walls, y, h, y1)) {'
variant unentered "$rest" "$never_rests" "$meets" "$never_meets"
variant unresolved "$rest" "$never_rests" "$meets" "$never_meets" \
    '        // Step k meets a stop (or starts at rest on one).' \
    '        y = y1;
        phase = rotate(rotate(phase, half), half);
        k = k + 1u;
        continue;
        // Step k meets a stop (or starts at rest on one).'

# run NAME SCENE...: median device seconds of interleaved runs.
declare -A times
measure() {
    for ((r = 0; r < runs; r++)); do
        for entry in "$@"; do
            t=$(LYAPSWEEP_SHADER_DIR="$work/${entry%@*}" "$bin" run "$work/${entry#*@}.toml" \
                --out "$work/out" --quiet 2>&1 | sed -n 's/.*(timestamp queries) \([0-9.]*\) s.*/\1/p')
            times[$entry]+="$t "
        done
    done
    for entry in "$@"; do
        printf '  %-22s %s\n' "$entry" "$(tr ' ' '\n' <<<"${times[$entry]}" | grep . | sort -n |
            awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}')"
    done
}
adapter=$(LYAPSWEEP_SHADER_DIR="$work/base" "$bin" run "$work/no-wall.toml" --out "$work/out" 2>&1 |
    sed -n 's/^  backend *gpu ([a-z0-9]*) on \(.*\)$/\1/p')
echo "device seconds on ${adapter:-(no adapter?)}, medians of $runs interleaved runs"
echo "1. code no invocation runs ($lines lines):"
measure base@no-wall never@no-wall no-trip@no-wall always@no-wall
echo "2. the impact kernel's resolution path:"
measure base@wall unentered@wall unresolved@wall base@no-wall
