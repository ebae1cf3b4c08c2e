"""Each Python FMU runs its own bundled code (packaging/isolate.py), never a copy of the same
module names already imported by the host or by another FMU."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
import textwrap
import zipfile

import pytest

from impedance_cosim.packaging import build
from impedance_cosim.packaging.isolate import ROOTS, IsolationError, rewrite_imports

RENAMES = {"impedance_cosim": "impedance_cosim_abc", "plant_model": "plant_model_abc"}


def test_imports_of_bundled_packages_are_rewritten():
    source = textwrap.dedent(
        """\
        from __future__ import annotations
        import math
        from impedance_cosim.fmi.model import (
            FmuModel,  # a comment
            ModelError,
        )
        from impedance_cosim import physics
        from plant_model.model import PlantModel as P
        from plant_modelx import y
        from . import sibling


        def f():
            from impedance_cosim.physics.arm import Arm
            return Arm
        """
    )
    out = rewrite_imports(source, RENAMES)
    assert "from impedance_cosim_abc.fmi.model import FmuModel, ModelError\n" in out
    assert "from impedance_cosim_abc import physics\n" in out
    assert "from plant_model_abc.model import PlantModel as P\n" in out
    assert "    from impedance_cosim_abc.physics.arm import Arm\n" in out
    assert "from plant_modelx import y\n" in out and "from . import sibling\n" in out
    assert "import math\n" in out and out.endswith("    return Arm\n")


def test_a_plain_import_of_a_bundled_package_is_refused():
    with pytest.raises(IsolationError, match=r"x.py:2: `import impedance_cosim.physics`"):
        rewrite_imports("import os\nimport impedance_cosim.physics\n", RENAMES, "x.py")


def test_every_built_fmu_imports_only_its_own_packages(fmu_dir):
    """Every bundled module of a built Python FMU (FMI 2.0) lives in a tagged package and
    imports none of ours by its plain name; slavemodule.txt names the tagged slave module."""
    for fmu in sorted(fmu_dir.glob("*.fmu")):
        with zipfile.ZipFile(fmu) as z:
            slave = z.read("resources/slavemodule.txt").decode().strip()
            tag = slave.rsplit("_", 1)[1]
            assert f"resources/{slave}.py" in z.namelist() and len(tag) == 12
            for name in z.namelist():
                if not name.endswith(".py") or name.startswith("resources/pythonfmu/"):
                    continue
                top = name.split("/")[1].removesuffix(".py")
                assert top.endswith(f"_{tag}"), f"{fmu.name}: {name} is not in a tagged package"
                for node in ast.walk(ast.parse(z.read(name))):
                    if isinstance(node, ast.ImportFrom) and node.level == 0:
                        assert node.module.split(".")[0] not in ROOTS, f"{name}: {node.module}"
                    elif isinstance(node, ast.Import):
                        assert not {a.name.split(".")[0] for a in node.names} & set(ROOTS)


VARIANT_RUN = """
import sys
import numpy as np
import plant_model.model  # the host has our plant imported, like the CLI and sweep workers
from impedance_cosim.cosim.master.master import Master
from impedance_cosim.cosim.master.options import RunOptions
from impedance_cosim.cosim.ssp.read import read_ssp

system = read_ssp(sys.argv[1])
original = Master(system, RunOptions(stop_time=0.5)).run()
swapped = Master(system, RunOptions(stop_time=0.5, fmu_files={"plant": sys.argv[2]})).run()
again = Master(system, RunOptions(stop_time=0.5)).run()
assert original.ok and swapped.ok and again.ok
pen = original.names.index("plant.penetration")
diff = swapped.data - original.data
print(float(np.max(np.abs(diff[:, pen] - 1.0))), float(np.max(np.abs(np.delete(diff, pen, 1)))),
      float(np.max(np.abs(again.data - original.data))))
"""


def test_a_modified_plant_runs_its_own_code_beside_ours(tmp_path, monkeypatch, ssp_path):
    """A plant FMU built from modified sources (its penetration output offset by 1 m) and ours,
    in one process that has also imported our plant_model: each runs its own code. Before the
    isolation, the modified FMU silently ran the host's plant."""
    repo = tmp_path / "repo"
    (repo / "impedance_cosim").mkdir(parents=True)
    for item in build.FMU_CORE:
        src = build.REPO / "impedance_cosim" / item
        (shutil.copytree if src.is_dir() else shutil.copy2)(src, repo / "impedance_cosim" / item)
    shutil.copytree(build.REPO / "plant_model", repo / "plant_model")
    model = repo / "plant_model" / "model.py"
    text = model.read_text()
    old = "pen = max(0.0, pose[0] - self.wall.wall_x)"
    assert text.count(old) == 1
    model.write_text(text.replace(old, "pen = 1.0 + max(0.0, pose[0] - self.wall.wall_x)"))
    monkeypatch.setattr(build, "REPO", repo)
    variant = build.build_fmu(build.FMUS["plant"], tmp_path / "variant")
    script = tmp_path / "variant_run.py"
    script.write_text(VARIANT_RUN)
    out = subprocess.run([sys.executable, str(script), str(ssp_path), str(variant)],
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert out.returncode == 0, out.stderr
    pen_error, other, repeat = map(float, out.stdout.split())
    assert pen_error == 0.0  # the variant's own code: penetration + 1
    assert other == 0.0  # nothing else changed
    assert repeat == 0.0  # ours again afterwards: still ours
