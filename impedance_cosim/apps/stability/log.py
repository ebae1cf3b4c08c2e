"""What `impedance-cosim stability` keeps while it works, so that Ctrl-C, SIGTERM or a failure
part-way loses no finished run, and `--resume` goes on from there.

- `<part>.runs.jsonl` (PartLog), while a part is under way: its plan on the first line (archive
  sha256, options, selection: checked on --resume), then one JSON line per finished run (or
  table row), appended and flushed as it finishes. --resume takes these instead of running them
  again; a torn or malformed line is run again. Removed once the part's table is written.
- `stability.run.json` (Record): the command's provenance and, per part, its plan and status
  (finished, interrupted, failed); --resume skips a finished part with the same plan.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Hashable
from pathlib import Path
from typing import Any

from impedance_cosim.apps.stability.bisection import StabilityError
from impedance_cosim.cosim.results import provenance

FORMAT = "impedance-cosim stability log 1"
RECORD = "stability.run.json"
Key = tuple[Hashable, ...]


def _key(value: Any) -> Key | None:
    """A record's key (a JSON list of names and numbers) as a tuple; None if it is not one."""
    if not isinstance(value, list) or not value:
        return None
    ok = all(isinstance(v, str) or (isinstance(v, int | float) and math.isfinite(v)) for v in value)
    return tuple(value) if ok else None


class PartLog:
    """The finished runs of one part on disk (see module docstring); use in a with-block.
    valid(key, data) says whether a kept record can be used (others are run again)."""

    def __init__(self, out: Path, part: str, plan: dict[str, Any], resume: bool,
                 valid: Callable[[Key, dict], bool] = lambda k, d: True) -> None:  # fmt: skip
        self.path = Path(out) / f"{part}.runs.jsonl"
        self.part, self.plan, self.resume, self.valid = part, plan, resume, valid
        self.kept: dict[Key, dict] = {}  # found on --resume
        self.added: dict[Key, dict] = {}  # finished by this command
        self._file: Any = None

    def __enter__(self) -> PartLog:
        self._load()
        lines = [{"format": FORMAT, "part": self.part, "plan": self.plan}]
        lines += [{"key": list(k), "data": d} for k, d in self.kept.items()]
        from impedance_cosim.util.atomic import LineFile, WriteError, atomic_write

        try:
            with atomic_write(self.path, "w", encoding="utf-8") as f:
                f.write("".join(json.dumps(line) + "\n" for line in lines))
            self._file = LineFile(self.path)
        except WriteError as exc:
            raise StabilityError(str(exc)) from None
        except OSError as exc:
            raise StabilityError(f"cannot write {self.path}: {exc.strerror or exc}") from None
        return self

    def __exit__(self, *exc: object) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    @property
    def runs(self) -> int:
        """Finished runs on disk: kept from before and added now."""
        return len(self.kept) + len(self.added)

    def get(self, key: Key) -> dict | None:
        """The data of a finished run (kept or added), None when it is to be run."""
        return self.kept.get(key) or self.added.get(key)

    def add(self, key: Key, data: dict[str, Any]) -> None:
        """A finished run: one line, flushed to disk before the next run starts. A signal
        meanwhile is handled once the line is on disk and counted (so what the command says it
        kept is what the file holds)."""
        import signal

        from impedance_cosim.util.atomic import WriteError
        from impedance_cosim.util.interrupt import StopSignals

        with StopSignals() as stop:
            try:
                self._file.append(json.dumps({"key": list(key), "data": data}) + "\n", sync=True)
            except WriteError as exc:  # e.g. a full disk: stop with one line; the log is whole
                note = f"it holds the {self.runs} finished runs before this one (--resume)"
                raise exc.with_note(note) from None
            self.added[key] = data
        if stop.signum is not None:
            signal.raise_signal(stop.signum)  # now, to the command's own handler

    def remove(self) -> None:
        """The part's table is written: the log is no longer needed."""
        self.__exit__()
        self.path.unlink(missing_ok=True)

    def _load(self) -> None:
        """Keep the valid runs of an existing log (on --resume, if its plan is this one's), or
        refuse to overwrite the finished runs of an interrupted part without --resume."""
        try:
            with open(self.path, encoding="utf-8") as f:
                lines = f.read().splitlines()
        except FileNotFoundError:
            return
        except (OSError, UnicodeDecodeError) as exc:
            raise StabilityError(f"cannot read {self.path}: {exc}") from None
        records = []
        for line in lines[1:]:
            try:
                item = json.loads(line)
            except ValueError:
                continue  # torn (the writer was killed mid-line): run it again
            key = _key(item.get("key")) if isinstance(item, dict) else None
            data = item.get("data") if key else None
            if isinstance(data, dict) and self.valid(key, data):
                records.append((key, data))
        if not self.resume:
            if records:
                raise StabilityError(
                    f"{self.path} holds {len(records)} finished runs of an interrupted "
                    f"`stability {self.part}`: add --resume to finish it, or remove it to start "
                    "over"
                )
            return
        try:
            head = json.loads(lines[0]) if lines else None
        except ValueError:
            head = None
        if not isinstance(head, dict) or head.get("format") != FORMAT:
            raise StabilityError(f"cannot resume from {self.path}: not a stability log")
        why = difference(head.get("plan"), self.plan)
        if why:
            raise StabilityError(f"cannot resume from {self.path}: {why}")
        self.kept = dict(records)


def difference(old: Any, new: dict[str, Any]) -> str | None:
    """The first way a stored plan differs from this command's, in words; None when equal."""
    if not isinstance(old, dict):
        return "it has no plan"
    for key in sorted(set(old) | set(new)):
        if old.get(key) != new.get(key):
            what = "the system archive differs" if key == "ssp_sha256" else (
                f"its {key} is {old.get(key)!r}, this command's {new.get(key)!r}")  # fmt: skip
            return f"it is another study: {what}"
    return None


class Record:
    """stability.run.json: the command's provenance and every part's status (see module
    docstring); parts of earlier commands into the same folder stay as they were."""

    def __init__(self, out: Path, command: list[str] | None, ssp: Path) -> None:
        self.path = Path(out) / RECORD
        self.command, self.ssp = command, ssp
        self.started = provenance.now_utc()
        self._clock = time.perf_counter()
        self.parts: dict[str, dict[str, Any]] = {}
        try:
            old = json.loads(self.path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError):
            old = {}
        parts = old.get("parts") if isinstance(old, dict) else None
        if isinstance(parts, dict):
            self.parts = {k: v for k, v in parts.items() if isinstance(v, dict)}
        self.mine: list[str] = []  # the parts of this command, in order

    def finished(self, part: str, plan: dict[str, Any]) -> bool:
        """The part finished earlier with this plan, and its table is still there."""
        entry = self.parts.get(part, {})
        table = entry.get("table")
        there = isinstance(table, str) and (self.path.parent / Path(table).name).is_file()
        return entry.get("status") == "finished" and entry.get("plan") == plan and there

    def keep(self, part: str) -> None:
        """A part finished earlier, kept as it is (--resume)."""
        self.mine.append(part)
        self.parts[part]["kept_by_resume"] = True

    def set(self, part: str, **fields: Any) -> None:
        """Fields of a part's entry (the first call of this command starts it anew)."""
        if part not in self.mine:
            self.mine.append(part)
            self.parts[part] = {}
        self.parts[part].update(fields)

    def kept(self) -> str:
        """What an interrupted or failed command kept, and how to finish it (one line)."""
        said = []
        for part in self.mine:
            entry = self.parts[part]
            if entry.get("status") == "finished":
                said.append(f"{part} finished ({self.path.parent / str(entry.get('table'))})")
            elif entry.get("runs"):
                log = self.path.parent / str(entry.get("log"))
                said.append(f"{part}: {entry['runs']} finished runs kept in {log}")
        if not said:
            return "no run had finished"
        return "; ".join(said) + "; to finish, run the same command with --resume"

    def data(self) -> dict[str, Any]:
        wall = time.perf_counter() - self._clock
        out = provenance.record([], self.started, wall, command=self.command, ssp=self.ssp)
        del out["runs"]
        out.update(parts=self.parts, this_command=self.mine)
        return out

    def write(self) -> None:
        """Write it (atomically); a record that cannot be written is one warning line."""
        import sys

        try:
            provenance.write(self.path, self.data())
        except OSError as exc:
            print(f"impedance-cosim stability: warning: no {self.path}: {exc}", file=sys.stderr)
