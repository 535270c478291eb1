#!/usr/bin/env bash
# tools/device_pack.sh [BUILD_DIR] — packs what a lent GPU machine needs to run this build, into
# the git-ignored folders .dev/ and .gl/ of the repo (carry both). Such a machine starts bare,
# without Debian's packages or ../shared, and reaches nothing outside itself:
#   .gl/           the Vulkan loader and GL dispatch packages (.deb, amd64), downloaded once;
#   .dev/bin/      sdfprune and sdfprune_tests from BUILD_DIR (default build);
#   .dev/libs.tar.xz  the shared libraries they load, but the C library's own and the Vulkan
#                  loader (the machine's driver brings what it needs);
#   .dev/scenes/   the reference scenes (../shared/scenes or $SDFPRUNE_SCENES), if present;
#   .dev/cli_path  the path compiled into sdfprune_tests for the CLI (tests run it there);
#   .dev/bin/sdfprune.base  with BASELINE=PATH, another sdfprune (an older build, say) to
#                  compare with on the machine (bench/gpu_steps.sh base=build/sdfprune.base ...).
# On the machine, `source tools/device_env.sh` sets everything up. One call then, for example:
#   source tools/device_env.sh && build/sdfprune_tests --gtest_filter='Gpu*'
# The tree that travels may hold 64 MiB: the script prints what it packed.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "${1:-$root/build}" && pwd)
scenes=${SDFPRUNE_SCENES:-$root/../shared/scenes}
cd "$root"
for b in sdfprune sdfprune_tests; do
  [ -x "$build/$b" ] || { echo "device_pack: $build/$b not found: build it first (make build)" >&2; exit 2; }
done
binaries=("$build/sdfprune" "$build/sdfprune_tests")
if [ -n "${BASELINE:-}" ]; then
  [ -x "$BASELINE" ] || { echo "device_pack: BASELINE $BASELINE is not an executable" >&2; exit 2; }
  binaries+=("$BASELINE")
fi

if ! ls .gl/libvulkan1_*.deb > /dev/null 2>&1; then
  echo "device_pack: downloading the Vulkan loader packages into .gl/" >&2
  lists=$(mktemp -d)
  mkdir -p .gl "$lists/partial"
  o=(-oAPT::Architecture=amd64 -oAPT::Architectures=amd64 "-oDir::State::Lists=$lists")
  apt-get "${o[@]}" -qq update
  (cd .gl && apt-get "${o[@]}" -qq download libvulkan1 libegl1 libglvnd0 libopengl0 libgl1 \
    libglx0 libgles2)
  rm -rf "$lists"
fi

rm -rf .dev
mkdir -p .dev/bin .dev/libs
cp "$build/sdfprune" "$build/sdfprune_tests" .dev/bin/
[ -n "${BASELINE:-}" ] && cp "$BASELINE" .dev/bin/sdfprune.base
echo "$build/sdfprune" > .dev/cli_path
# Every library a binary loads, by its resolved path, but those of glibc and the loader.
ldd "${binaries[@]}" | awk '$2 == "=>" && $3 ~ /^\// { print $3 }' |
  sort -u | grep -Ev '/(libc|libm|libdl|libpthread|librt|ld-linux[^/]*|libvulkan)\.so' |
  while read -r lib; do cp -L "$lib" .dev/libs/; done
tar -C .dev -cJf .dev/libs.tar.xz libs
rm -rf .dev/libs
if [ -d "$scenes" ]; then
  cp -r "$scenes" .dev/scenes
else
  echo "device_pack: no reference scenes in $scenes: only generated scenes will be there" >&2
fi
du -sh .dev .gl | sed 's/^/device_pack: /' >&2
