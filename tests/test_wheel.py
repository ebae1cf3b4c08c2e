"""The wheel carries the built FMUs and system archives (setup.py, packaging/wheel_fmus.py): built
from a copy of the checkout's files, installed into a fresh venv and run with a PATH that has no C
compiler, it runs the paper's scenario from its packaged FMUs, and `impedance-cosim fmus
--copy-to` gives the wheel's own bytes."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import tarfile
import zipfile
from pathlib import Path

import pytest

from impedance_cosim.packaging.wheel_fmus import REQUIRED

REPO = Path(__file__).resolve().parents[1]
DATA = "impedance_cosim/_fmus/"
TIMEOUT = 1800  # s per command: an upper bound for a hang, not a duration check


def _run(cmd: list, **kwargs) -> subprocess.CompletedProcess:
    done = subprocess.run([str(c) for c in cmd], capture_output=True, text=True,
                          timeout=TIMEOUT, check=False, **kwargs)  # fmt: skip
    assert done.returncode == 0, f"{cmd}: {done.returncode}\n{done.stdout}\n{done.stderr}"
    return done


def _sources(dest: Path) -> Path:
    """The checkout's files that git tracks or would (not the ignored: no build/, no fmus/),
    copied to dest."""
    listed = _run(["git", "ls-files", "-z", "-co", "--exclude-standard"], cwd=REPO).stdout
    listed = listed.split("\0")
    for name in filter(None, listed):
        if (REPO / name).is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / name, dest / name)
    return dest


def _no_compiler_env(venv: Path, tmp: Path) -> dict[str, str]:
    """The environment of a user without a C compiler: PATH is the venv's bin and a folder with
    links to the few tools a run may call, no CC, and an empty cache (no compiled loop)."""
    tools = tmp / "tools"
    tools.mkdir()
    for tool in ("sh", "env", "uname"):
        if found := shutil.which(tool):
            (tools / tool).symlink_to(found)
    path = os.pathsep.join([str(venv / "bin"), str(tools)])
    for compiler in ("gcc", "cc", "clang", "x86_64-linux-gnu-gcc", "tcc"):
        assert shutil.which(compiler, path=path) is None, compiler
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "VIRTUAL_ENV", "PYTHONPATH")}
    (tmp / "home").mkdir()
    return {**env, "PATH": path, "HOME": str(tmp / "home"), "XDG_CACHE_HOME": str(tmp / "cache")}


@pytest.mark.slow
def test_the_installed_wheel_runs_without_a_compiler(tmp_path: Path) -> None:
    fmus = tmp_path / "fmus"
    _run([sys.executable, "-m", "impedance_cosim.cli", "build", "--out", fmus])
    src = _sources(tmp_path / "src")
    env = {**os.environ, "IMPCOSIM_WHEEL_FMUS": str(fmus)}
    # plain `python -m build`: the sdist (which carries fmus/), then the wheel built from it
    _run([sys.executable, "-m", "build", "--outdir", tmp_path / "dist", src], env=env)
    (wheel,) = (tmp_path / "dist").glob("impedance_cosim-*-py3-none-any.whl")
    (sdist,) = (tmp_path / "dist").glob("impedance_cosim-*.tar.gz")
    with tarfile.open(sdist) as t:
        in_sdist = {
            n.split("/fmus/", 1)[1]
            for n in t.getnames()
            if "/fmus/" in n and t.getmember(n).isfile()
        }
    assert all(any(n == r or n.startswith(r + "/") for n in in_sdist) for r in REQUIRED)
    with zipfile.ZipFile(wheel) as z:
        packaged = {n[len(DATA) :]: z.read(n) for n in z.namelist() if n.startswith(DATA)}
    assert all(any(n == r or n.startswith(r + "/") for n in packaged) for r in REQUIRED)
    built = {p.relative_to(fmus).as_posix(): p.read_bytes() for p in fmus.rglob("*")
             if p.is_file() and p.name != "README.md" and not p.name.startswith(".")}  # fmt: skip
    assert packaged == built  # every file the build wrote, as it wrote it

    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", venv])
    _run([venv / "bin" / "python", "-m", "pip", "install", "-q", wheel])
    env = _no_compiler_env(venv, tmp_path)
    work = tmp_path / "work"  # a folder with no fmus/ in it
    work.mkdir()
    cli = venv / "bin" / "impedance-cosim"
    done = _run([cli, "run", "--stop", "2", "--out", tmp_path / "out", "--no-progress"],
                env=env, cwd=work)  # fmt: skip
    assert "building" not in done.stderr, done.stderr  # nothing built: the packaged archive ran
    system = json.loads((tmp_path / "out" / "run.json").read_text())["system"]
    assert system["ssp"].startswith(str(venv)), system  # the installed package's archive
    assert system["ssp"].endswith("/impedance_cosim/_fmus/PaperScenario.ssp"), system
    assert system["sha256"] == hashlib.sha256(packaged["PaperScenario.ssp"]).hexdigest()
    assert not (work / "fmus").exists()

    listed = _run([cli, "fmus"], env=env, cwd=work).stdout.splitlines()
    assert listed[-1].startswith(f"{len(packaged)} files in ") and "_fmus" in listed[-1]
    _run([cli, "fmus", "--copy-to", tmp_path / "x"], env=env, cwd=work)
    copied = {p.relative_to(tmp_path / "x").as_posix(): p.read_bytes()
              for p in (tmp_path / "x").rglob("*") if p.is_file()}  # fmt: skip
    assert copied == packaged
