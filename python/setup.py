"""Builds isotope._isotope with CMake from the repository this folder is part of.

The module links the C++ library statically, so the C++ build is the repository's own
(CMakeLists.txt with ISOTOPE_PYTHON=ON). ISOTOPE_BUILD_DIR names a build tree to reuse (CI reuses
its Release tree, build-ci, so the library is not compiled twice); otherwise setuptools' temporary
build folder is used. ISOTOPE_BUILD_JOBS bounds the compile jobs (default: all cores).
"""

import os
import pathlib
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent


class CMakeExtension(Extension):
    def __init__(self, name):
        super().__init__(name, sources=[])


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        build = pathlib.Path(os.environ.get("ISOTOPE_BUILD_DIR") or pathlib.Path(self.build_temp) / "cmake").resolve()
        build.mkdir(parents=True, exist_ok=True)
        configure = ["cmake", "-S", str(ROOT), "-B", str(build), "-DISOTOPE_PYTHON=ON",
                     f"-DPython_EXECUTABLE={sys.executable}"]
        if not (build / "CMakeCache.txt").exists():  # a fresh tree: the module and what it needs only
            configure += ["-DCMAKE_BUILD_TYPE=Release", "-DISOTOPE_BUILD_TESTS=OFF", "-DISOTOPE_BUILD_BENCH=OFF"]
        subprocess.run(configure, check=True)
        jobs = os.environ.get("ISOTOPE_BUILD_JOBS", str(os.cpu_count() or 1))
        subprocess.run(["cmake", "--build", str(build), "--target", "_isotope", "-j", jobs], check=True)
        built = next((build / "python").glob("_isotope*.so"))
        target = pathlib.Path(self.get_ext_fullpath(ext.name))
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(built, target)


setup(
    packages=["isotope"],
    ext_modules=[CMakeExtension("isotope._isotope")],
    cmdclass={"build_ext": CMakeBuild},
    zip_safe=False,
)
