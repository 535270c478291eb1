# tools/device_env.sh — sourced on a lent GPU machine, in the repo's root, with .dev/ and .gl/
# carried (tools/device_pack.sh made them here): installs the Vulkan loader, unpacks the
# libraries, points the NVIDIA driver's Vulkan ICD and the scenes at the build, and puts the
# binaries at build/ and at the CLI path compiled into sdfprune_tests. Then `build/sdfprune`,
# `bench/*.sh build` and `build/sdfprune_tests` run as they do here.
if [ ! -d .dev/bin ] || [ ! -d .gl ]; then
  echo "device_env: .dev/bin or .gl missing: run tools/device_pack.sh here and carry both" >&2
  return 2 2> /dev/null || exit 2
fi
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
rm -rf /tmp/libs
tar -C /tmp -xJf .dev/libs.tar.xz
export LD_LIBRARY_PATH=/tmp/libs${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
[ -d .dev/scenes ] && export SDFPRUNE_SCENES=$PWD/.dev/scenes
mkdir -p build
cp .dev/bin/sdfprune .dev/bin/sdfprune_tests build/
[ -f .dev/bin/sdfprune.base ] && cp .dev/bin/sdfprune.base build/
cli=$(cat .dev/cli_path)
if [ "$(realpath -m "$cli")" != "$(realpath -m build/sdfprune)" ]; then
  mkdir -p "$(dirname "$cli")"
  cp .dev/bin/sdfprune "$cli"
fi
# The device the Vulkan backend takes (its stats line names it), as a check that all loads.
build/sdfprune stats builtin:demo --backend vulkan --grid 16 --json | tail -n 1 |
  sed -E 's/.*"device":"([^"]*)".*/device_env: Vulkan device: \1/'
