"""The committed fuzz corpora (fuzz/corpus/<target>/) replayed through every fuzz target, so that
each input a fuzzer once found interesting (and each finding's reproducer, kept there) stays a
regression test. No timing: each Python target's entry() once per file (no atheris needed);
each C target built with clang's address and undefined sanitizers and the harness's own main()
(no libFuzzer), which replays the files and must exit 0. See fuzz/ and docs/failures.md."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "fuzz"))
import targets  # noqa: E402


@pytest.fixture(scope="module")
def fmus(fmi3_dir: Path, monkeypatch_module) -> Path:
    """The build output the targets read (native/, fmi3/ and the system archives)."""
    out = fmi3_dir.parent
    monkeypatch_module.setenv("IMPCOSIM_FUZZ_FMUS", str(out))
    return out


@pytest.fixture(scope="module")
def closed_loop(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A build output holding fmi3/PaperClosedLoop-observer.fmu (a folder of its own: other
    tests count the session's FMUs)."""
    from impedance_cosim.packaging.closedloop import build_closed_loop3

    out = tmp_path_factory.mktemp("fuzz-closedloop")
    build_closed_loop3("observer", out / "fmi3")
    return out


@pytest.fixture(scope="module")
def monkeypatch_module():
    with pytest.MonkeyPatch.context() as mp:
        yield mp


def test_every_target_has_a_corpus():
    for name in [*targets.C_TARGETS, *targets.PY_TARGETS]:
        files = targets.corpus(name)
        assert files, f"fuzz/corpus/{name}/ is empty"
        limit = 150 if "_calls_" in name else 60  # call sequences: ~100 files of ~130 bytes
        assert len(files) <= limit, f"fuzz/corpus/{name}/: {len(files)} files (-merge=1 them)"


@pytest.mark.parametrize("name", targets.PY_TARGETS)
def test_python_target_replays_its_corpus(name, fmus):
    entry = targets.python_module(name).entry
    for path in targets.corpus(name):
        entry(path.read_bytes())  # anything but the reader's own error class fails here


@pytest.mark.parametrize("name", list(targets.C_TARGETS))
def test_c_target_replays_its_corpus(name, fmus, tmp_path, request):
    if not targets.clang():
        pytest.skip("clang is not installed (apt-get install clang libclang-rt-14-dev)")
    if not (fmus / targets.C_TARGETS[name][1]).exists():  # the closed loop: built on request
        fmus = request.getfixturevalue("closed_loop")
    exe = targets.build_c(name, fmus, tmp_path, libfuzzer=False)
    files = [str(p) for p in targets.corpus(name)]
    done = subprocess.run([str(exe), *files], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-4000:]
    assert f"replayed {len(files)} files" in done.stdout
