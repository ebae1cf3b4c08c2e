"""The wheel carries the built FMUs and system archives (what `impedance-cosim build` writes into
fmus/) as package data in impedance_cosim/_fmus, so that an installed wheel runs the paper's
scenario without a C compiler (docs/fmus-platforms.md#installing-the-fmus-from-a-wheel). They are
copied, not built, here: build them first (`impedance-cosim build`); IMPCOSIM_WHEEL_FMUS names
another build folder. The sdist carries them in fmus/, so that `python -m build` (an sdist, then
a wheel built from it) gives the same wheel. Everything else is in pyproject.toml."""

import functools
import importlib.util
import os
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.sdist import sdist

HERE = Path(__file__).resolve().parent


@functools.cache
def _wheel_fmus():
    """impedance_cosim/packaging/wheel_fmus.py, loaded by path (standard library only), once."""
    path = HERE / "impedance_cosim" / "packaging" / "wheel_fmus.py"
    spec = importlib.util.spec_from_file_location("_impcosim_wheel_fmus", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _built_fmus():
    """(folder, file names) of the complete, current build the packages carry; exits naming the
    command to run when there is none."""
    wheel_fmus = _wheel_fmus()
    src = Path(os.environ.get("IMPCOSIM_WHEEL_FMUS") or HERE / "fmus").resolve()
    try:
        return src, wheel_fmus.check_built(src, HERE)
    except wheel_fmus.NotBuiltError as exc:
        raise SystemExit(f"error: the wheel carries the built FMUs: {exc}") from None


class SdistWithFmus(sdist):
    """sdist, with the built FMUs and archives in the release tree's fmus/."""

    def make_release_tree(self, base_dir, files):
        super().make_release_tree(base_dir, files)
        src, names = _built_fmus()
        _wheel_fmus().copy_files(src, Path(base_dir) / "fmus", names)
        print(f"copied {len(names)} FMUs and archives from {src} into the sdist")


class BuildPyWithFmus(build_py):
    """build_py, then the built FMUs and archives into the build's impedance_cosim/_fmus."""

    def run(self):
        super().run()
        if self.editable_mode:  # `pip install -e .`: a clone uses its own fmus/
            return
        src, names = _built_fmus()
        dst = Path(self.build_lib) / "impedance_cosim" / "_fmus"
        shutil.rmtree(dst, ignore_errors=True)  # nothing left from an earlier build
        _wheel_fmus().copy_files(src, dst, names)
        print(f"copied {len(names)} FMUs and archives from {src} into {dst}")


setup(cmdclass={"build_py": BuildPyWithFmus, "sdist": SdistWithFmus})
