"""setup.py — builds the extension module sdfprune._sdfprune with this repository's CMake.

pyproject.toml explains the choice. The CMake build tree is build/python (incremental across
installs); the environment may set SDFPRUNE_VULKAN=1 to build the Vulkan backend in,
SDFPRUNE_BUILD_DIR to build in an existing
CMake tree instead (its options kept; `make test` uses the main build/), CMAKE_BUILD_PARALLEL_LEVEL for the job count.
"""
import os
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent


class CMakeExtension(Extension):
    def __init__(self, name):
        super().__init__(name, sources=[])


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        shared = os.environ.get("SDFPRUNE_BUILD_DIR")
        build_dir = Path(shared) if shared else ROOT / "build" / "python"
        build_dir.mkdir(parents=True, exist_ok=True)
        configure = ["cmake", "-S", str(ROOT), "-B", str(build_dir),
                     "-DSDFPRUNE_PYTHON=ON", f"-DPython_EXECUTABLE={sys.executable}"]
        if not shared or not (build_dir / "CMakeCache.txt").exists():
            # A build tree of the package's own: the engine library and the module only.
            vulkan = os.environ.get("SDFPRUNE_VULKAN", "0") not in ("", "0", "OFF", "off")
            generator = ["-G", "Ninja"] if shutil.which("ninja") else []
            configure += [*generator, "-DCMAKE_BUILD_TYPE=Release", "-DSDFPRUNE_CLI=OFF",
                          "-DSDFPRUNE_TESTS=OFF", "-DSDFPRUNE_BENCH=OFF",
                          f"-DSDFPRUNE_VULKAN={'ON' if vulkan else 'OFF'}"]
        # else: an existing tree (make test passes the main build/): its options are kept and
        # only the module is added, so the engine is not compiled twice.
        subprocess.check_call(configure)
        jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL", str(os.cpu_count() or 2))
        subprocess.check_call(["cmake", "--build", str(build_dir), "--target", "_sdfprune",
                               "-j", jobs])
        built = sorted(build_dir.glob("_sdfprune*.so"))
        if not built:
            raise RuntimeError(f"the CMake build made no _sdfprune module in {build_dir}")
        target = Path(self.get_ext_fullpath(ext.name))
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(built[-1], target)


setup(ext_modules=[CMakeExtension("sdfprune._sdfprune")], cmdclass={"build_ext": CMakeBuild})
