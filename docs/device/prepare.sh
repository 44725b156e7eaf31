#!/usr/bin/env bash
# Prepares, on the project's machine, what docs/device/check.sh runs on a
# lent NVIDIA machine (the device tool's `nvidia-h100-x1`): the release
# binaries, compressed to travel within the 64 MiB a call carries, and the
# Vulkan loader and libglvnd as Debian packages (the machine has the NVIDIA
# driver but no loader, and reaches no network). Run from the repository's
# root; then call the device tool with
#   command: bash docs/device/check.sh
#   carry:   [".devbin", ".gl"]
#   timeout_s: 540
# and read the files it brings back (docs/device/README.md).
set -euo pipefail
cd "$(dirname "$0")/../.."
grep -qx '/.devbin/' .git/info/exclude 2>/dev/null || echo /.devbin/ >>.git/info/exclude
grep -qx '/.gl/' .git/info/exclude 2>/dev/null || echo /.gl/ >>.git/info/exclude

cargo build --release --locked
# The newest of each test and bench binary is the one just built.
built() {
    cargo "$@" --locked --no-run --message-format=json 2>/dev/null |
        python3 -c 'import json,sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable"):
        print(m["executable"])'
}
tests=$(built test --release --test gpu --test gpu_models --test math64)
bench=$(built bench --bench lane_steps)
rm -rf .devbin && mkdir -p .devbin
cp target/release/lyapsweep .devbin/lyapsweep
for f in $tests $bench; do
    name=$(basename "$f" | sed 's/-[0-9a-f]*$//')
    cp "$f" ".devbin/$name"
done
git rev-parse HEAD >.devbin/commit
# An earlier commit's CLI beside this one's (BEFORE=path to its release
# binary, COMMIT_BEFORE=its commit), to compare on the same card.
if [ -n "${BEFORE:-}" ]; then
    cp "$BEFORE" .devbin/lyapsweep-before
    echo "${COMMIT_BEFORE:-unknown}" >.devbin/commit-before
fi
for f in .devbin/*; do
    case $f in *commit*) ;; *) xz -T0 -6 "$f" ;; esac
done
du -sh .devbin

if [ ! -d .gl ] || ! ls .gl/*.deb >/dev/null 2>&1; then
    mkdir -p .gl /tmp/amd64/partial
    o='-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 -oDir::State::Lists=/tmp/amd64'
    # shellcheck disable=SC2086
    apt-get $o update -qq
    # shellcheck disable=SC2086
    (cd .gl && apt-get $o download libvulkan1 libglvnd0 libegl1 libglx0 libgl1 libopengl0 libgles2)
fi
du -sh .gl
