"""The README and docs/*.md as tests: every relative link resolves (files and #anchors), and every
fenced ```sh and ```python block runs, collected from the Markdown at test time.

Convention (also in the README's "The examples in these pages run in the tests"):
- A fenced ```sh block is a list of commands (a line ending in ``\\`` continues), run in order
  as one bash script in a fresh working folder per block, in which ``fmus`` is the checkout's built
  fmus/ (so ``--ssp fmus/...`` works and anything a command writes lands in the temporary folder).
  A command must exit 0, unless it ends in a comment ``# exits N: why``.
- A fenced ```python block is run as one script (``python -c``) in such a folder; it must exit 0.
- Other blocks (```text, ```console, plain ```) are output or pictures and are not run. A ```py
  block is the listing of a file of the checkout (examples/own_robot.py in docs/hil.md): not run
  here, its file is run by its own test (tests/test_examples.py, which also checks the listing).
- The folder also has ``examples``, the checkout's examples/ (``python examples/own_robot.py``).
- No page is longer than MAX_LINES: a longer one is split, guide apart from reference.
- Setup that CI's ``.ci/run`` executes itself (making the venv, activating it, installing this
  package, running the whole suite) is not re-run: such leading ``&&`` parts are stripped from a
  command (SETUP below), and a block may be marked ``<!-- not run: why -->`` on the line before it
  only when every command in it is such setup.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]

# What .ci/run does before the tests (it makes the venv, activates it, installs the package with
# its dev extras and runs the suite, which contains this file): not run again here.
SETUP = [
    r"python3? -m venv \.venv",
    r"\. \.venv/bin/activate",
    r"source \.venv/bin/activate",
    r"(python3? -m )?pip install( -q| --quiet)* -e (\.|\"\.\[dev\]\"|'\.\[dev\]')",
    r"python3? -m pytest( .*)?",  # the suite itself, any tier (docs/development.md)
]
EXIT = re.compile(r"#\s*exits (\d+)\b")
FENCE = re.compile(r"^```(\S*)\s*$")
NOT_RUN = re.compile(r"^<!--\s*not run:\s*\S.*-->\s*$")
TIMEOUT = 300  # s per command: an upper bound for a hang, not a duration check
MAX_LINES = 300  # per page: a page a user can read to its end

# At least this many are collected, so blocks cannot silently stop being run (e.g. a fence
# renamed). Today exactly these many: change the numbers deliberately with the examples.
MIN_COMMANDS = 40
MIN_SNIPPETS = 10


@dataclass
class Block:
    """A fenced code block of a page: its language, first line number, text, not-run reason."""

    page: Path
    lang: str
    line: int
    text: str
    not_run: str | None

    @property
    def id(self) -> str:
        return f"{self.page.relative_to(REPO)}:{self.line}"


def blocks(page: Path) -> list[Block]:
    """Every fenced code block of a Markdown page, in order."""
    out, lines, i = [], page.read_text().split("\n"), 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        start, body = i, []
        i += 1
        while i < len(lines) and not lines[i].startswith("```"):
            body.append(lines[i])
            i += 1
        prev = next((s for s in reversed(lines[:start]) if s.strip()), "")
        reason = prev.strip() if NOT_RUN.match(prev.strip()) else None
        out.append(Block(page, m.group(1).lower(), start + 1, "\n".join(body), reason))
        i += 1
    return out


def all_blocks() -> list[Block]:
    return [b for page in PAGES for b in blocks(page)]


def commands(block: Block) -> list[str]:
    """The commands of a sh block: continuation lines joined, comment-only and blank lines out."""
    out, cur = [], ""
    for raw in block.text.split("\n"):
        line = raw.rstrip()
        if line.endswith("\\"):
            cur += line[:-1] + " "
            continue
        cur += line
        if cur.strip() and not cur.strip().startswith("#"):
            out.append(cur.strip())
        cur = ""
    return out


def strip_setup(command: str) -> str:
    """The command without its leading setup parts (what .ci/run has already done)."""
    parts = [p.strip() for p in command.split("&&")]
    while parts and any(re.fullmatch(s, parts[0]) for s in SETUP):
        parts.pop(0)
    return " && ".join(parts)


def expected_status(command: str) -> int:
    """0, or N from a trailing ``# exits N: why`` comment."""
    m = EXIT.search(command)
    return int(m.group(1)) if m else 0


SH = [b for b in all_blocks() if b.lang == "sh" and b.not_run is None]
PY = [b for b in all_blocks() if b.lang == "python" and b.not_run is None]


@pytest.fixture(scope="module")
def built() -> Path:
    """The checkout's fmus/, built once if an archive the pages use is missing or older than its
    Python sources (as `impedance-cosim run` decides; the pages' own `impedance-cosim build`
    rebuilds everything anyway)."""
    from impedance_cosim.apps.build_cmd import stale

    fmus = REPO / "fmus"
    names = ["PaperScenario.ssp", "PaperScenario-native.ssp", "PaperScenario-fmi3.ssp",
             "PaperScenario-fmi3-ssp2.ssp", "native/PaperClosedLoop-observer.fmu"]  # fmt: skip
    if any(stale(fmus / n) for n in [*names, "BridgePlant.fmu"]):
        subprocess.run(
            [sys.executable, "-m", "impedance_cosim", "build"], cwd=REPO, env=environment(),
            check=True,
        )  # fmt: skip
    return fmus


def environment() -> dict[str, str]:
    """The environment of the README's commands: this venv's bin first on PATH."""
    env = dict(os.environ)
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    env["MPLBACKEND"] = "Agg"
    return env


def workdir(tmp_path: Path, fmus: Path) -> Path:
    """A fresh folder with `fmus` the built FMUs: where a page's commands run and write."""
    work = tmp_path / "work"
    work.mkdir()
    (work / "fmus").symlink_to(fmus)
    (work / "examples").symlink_to(REPO / "examples")
    return work


def run(argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    """Run argv in its own process group, and end whatever of that group is left afterwards
    (a block's background job, e.g. a robot, when a later command failed)."""
    proc = subprocess.Popen(
        argv, cwd=cwd, env=environment(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, start_new_session=True,
    )  # fmt: skip
    try:
        out, err = proc.communicate(timeout=TIMEOUT)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.communicate()
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def script(block: Block) -> str:
    """The block as one bash script that checks each command's exit status as it goes (one
    script, so `cmd &` and a later `kill $!` work as in a terminal)."""
    out = []
    for n, command in enumerate(commands(block)):
        todo = strip_setup(command)
        if not todo:
            continue
        want = expected_status(command)
        out.append(todo)
        if not re.sub(r"\s+#.*$", "", todo).endswith("&"):
            out.append(
                f"s=$?; if [ $s -ne {want} ]; then "
                f"echo 'command {n + 1} exited '$s', the docs say {want}' >&2; exit 99; fi"
            )
    return "\n".join(out) + "\n"


@pytest.mark.parametrize("block", SH, ids=[b.id for b in SH])
@pytest.mark.slow
def test_shell_block_runs(block: Block, built: Path, tmp_path: Path) -> None:
    """Each command of the block exits with the status the docs give (0 unless `# exits N`)."""
    work = workdir(tmp_path, built)
    p = run(["bash", "-c", script(block)], work)
    assert p.returncode == 0, (
        f"{block.id}:\n{block.text}\nstdout: {p.stdout[-2000:]}\nstderr: {p.stderr[-3000:]}"
    )


@pytest.mark.parametrize("block", PY, ids=[b.id for b in PY])
@pytest.mark.slow
def test_python_block_runs(block: Block, built: Path, tmp_path: Path) -> None:
    """The snippet runs to its end in a fresh folder."""
    p = run([sys.executable, "-c", block.text], workdir(tmp_path, built))
    assert p.returncode == 0, f"{block.id} failed:\n{p.stdout[-2000:]}\n{p.stderr[-3000:]}"


def test_enough_blocks_are_collected() -> None:
    """The runnable examples are found (a renamed fence would drop them silently)."""
    n = sum(len([c for c in commands(b) if strip_setup(c)]) for b in SH)
    assert n >= MIN_COMMANDS, f"only {n} shell commands collected from the docs"
    assert len(PY) >= MIN_SNIPPETS, f"only {len(PY)} Python snippets collected from the docs"


def test_not_run_marks_only_setup() -> None:
    """`<!-- not run -->` is allowed only on blocks that are all CI setup (.ci/run does them)."""
    for b in all_blocks():
        if b.not_run is not None:
            assert b.lang in ("sh", "python"), f"{b.id}: 'not run' on a block that never runs"
            rest = [c for c in commands(b) if strip_setup(c)]
            assert not rest, f"{b.id}: marked not run but has {rest}"


@pytest.mark.parametrize("page", PAGES, ids=[str(p.relative_to(REPO)) for p in PAGES])
def test_no_page_is_longer_than_max_lines(page: Path) -> None:
    """README.md and every docs/*.md page has at most MAX_LINES lines (split a longer one: the
    guide on one page, the reference on another)."""
    n = len(page.read_text().splitlines())
    assert n <= MAX_LINES, f"{page.relative_to(REPO)} has {n} lines (at most {MAX_LINES})"


def test_code_blocks_have_a_language() -> None:
    """Every fence names what it is, so a command cannot hide in an unlabelled block."""
    for b in all_blocks():
        assert b.lang, f"{b.id}: a fenced block without a language (sh, python, text)"


def test_setup_parts_are_what_ci_runs() -> None:
    """The stripped setup is what .ci/run does: a venv, its activation, the install, the tests."""
    ci = (REPO / ".ci" / "run").read_text()
    steps = ["python3 -m venv .venv", ". .venv/bin/activate", 'pip install --quiet -e ".[dev]"']
    for step in steps:
        assert step in ci
    assert re.search(r"^python -m pytest -n auto --durations=25$", ci, re.M)


# Links ------------------------------------------------------------------------------------------

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def prose(page: Path) -> str:
    """The page without its fenced blocks and inline code (links there are not links)."""
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)
    return re.sub(r"`[^`\n]*`", "", text)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"`", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(page: Path) -> set[str]:
    """Every heading anchor of a page (repeated headings get -1, -2, ... as on GitHub)."""
    seen: dict[str, int] = {}
    out = set()
    text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)
    for m in re.finditer(r"^#{1,6}\s+(.*?)\s*#*\s*$", text, re.M):
        s = slug(m.group(1))
        n = seen.get(s, 0)
        out.add(s if n == 0 else f"{s}-{n}")
        seen[s] = n + 1
    return out


def test_slug_matches_github() -> None:
    assert slug("The plant FMU (`PumaPlant`)") == "the-plant-fmu-pumaplant"
    assert slug("Platforms: which FMU runs where") == "platforms-which-fmu-runs-where"
    assert slug("The FMI 3.0 edition") == "the-fmi-30-edition"


LINKS = [(page, target) for page in PAGES for target in LINK.findall(prose(page))]


@pytest.mark.parametrize(
    "page,target", LINKS, ids=[f"{p.relative_to(REPO)}->{t}" for p, t in LINKS]
)
def test_relative_link_resolves(page: Path, target: str) -> None:
    """A relative link names a file of the checkout, and its #anchor a heading of that page."""
    if re.match(r"^[a-z]+:", target):  # http:, https:, mailto:
        return
    path, _, anchor = target.partition("#")
    dest = (page.parent / path).resolve() if path else page
    assert dest.exists(), f"{page.relative_to(REPO)}: link to {target}: no such file"
    if anchor:
        assert dest.suffix == ".md", f"{page.relative_to(REPO)}: anchor into a non-Markdown file"
        assert anchor in anchors(dest), (
            f"{page.relative_to(REPO)}: link to {target}: no heading with that anchor"
        )


def test_links_are_collected() -> None:
    assert len(LINKS) >= 20
    assert any("#" in t for _, t in LINKS)


DEFAULT_OUT = {"run": "results", "swap": "results/swap", "sweep": "results/sweep",
               "stability": "results/stability"}  # fmt: skip
QUICK_START = "impedance-cosim run"  # the README's quick start: the paper's results in results/


def result_folders() -> list[tuple[str, str, str]]:
    """(block id, command, output folder) of every command in the pages' sh blocks that writes
    results into results/ (run, swap, sweep, stability; --out or the command's default)."""
    import shlex

    found = []
    for block in SH:
        for command in commands(block):
            if expected_status(command) == 2:  # bad input: writes nothing
                continue
            for part in strip_setup(command).split("&&"):
                words = shlex.split(re.sub(r"\s+#.*$", "", part))
                if len(words) < 2 or words[0] != "impedance-cosim" or words[1] not in DEFAULT_OUT:
                    continue
                if "--help" in words or "-h" in words or "--list-parameters" in words:
                    continue
                out = DEFAULT_OUT[words[1]]
                for k, w in enumerate(words[:-1]):
                    if w == "--out":
                        out = words[k + 1]
                out = out.rstrip("/")
                if out == "results" or out.startswith("results/"):
                    found.append((block.id, " ".join(words), out))
    return found


def test_examples_do_not_write_over_the_quick_start_or_each_other() -> None:
    """Issue 35, item 1: the README's examples wrote into results/ over the quick start's paper
    results (the native run replaced report.html with a 2 s run, --realtime removed the
    *-jacobi.csv files). Every example command that writes into results/ has its own folder;
    only the quick start writes results/ itself."""
    found = result_folders()
    assert (found[0][1], found[0][2]) == (QUICK_START, "results"), found[0]
    assert len(found) > 10, found  # the commands are collected
    by_folder: dict[str, list[str]] = {}
    for where, command, out in found[1:]:
        if "--resume" not in command.split():  # continues the folder of the command before it
            by_folder.setdefault(out, []).append(f"{where}: {command}")
    assert "results" not in by_folder, by_folder.get("results")
    shared = {out: cmds for out, cmds in by_folder.items() if len(cmds) > 1}
    assert not shared, shared


# Words that tell the project's work history rather than what the software does; user pages
# (all but docs/development.md, the developers' page with its before/after table) avoid them.
HISTORY = re.compile(
    r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b"  # a commit hash
    r"|\bissue #?\d+|\buntil now\b|\bbefore (?:these|this|the) changes?\b|\bused to be\b",
    re.IGNORECASE,
)
USER_PAGES = [p for p in PAGES if p.name != "development.md"]


@pytest.mark.parametrize("page", USER_PAGES, ids=[str(p.relative_to(REPO)) for p in USER_PAGES])
def test_user_pages_speak_of_the_software_not_its_history(page: Path) -> None:
    """No commit hashes, issue numbers or before/after wording in a user page."""
    found = [
        f"{page.name}:{n}: {m.group(0)!r}"
        for n, line in enumerate(page.read_text().splitlines(), 1)
        for m in HISTORY.finditer(line)
    ]
    assert not found, found
