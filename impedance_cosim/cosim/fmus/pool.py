"""FMU instances reused from run to run within one process: a run takes an idle instance (or a
new one) and gives it back after fmi2Terminate; it is reset (fmi2Reset: back to the state right
after instantiation, every start value restored) and kept for the next run of the same FMU file.
A sweep worker saves the library load and instantiation per run (~5 ms for each of our FMUs);
results are the same bit for bit (tests/test_sweep_batch.py)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

from impedance_cosim.cosim.fmus.fmi2 import FmuError, FmuInstance


class InstancePool:
    """Idle instances by (FMU file version, instance name); see module docstring. An instance
    that failed (an FMI error, a failed terminate or reset) is freed, never reused."""

    def __init__(self, limit: int = 8) -> None:
        self.limit = limit  # idle instances kept per key (a system needs one per component)
        self._idle: dict[tuple, list[FmuInstance]] = {}
        self.reused = 0  # instances handed out again (for tests and benchmarks)

    @staticmethod
    def _key(path: Path, name: str) -> tuple:
        path = Path(path).resolve()
        st = path.stat()
        return (str(path), st.st_mtime_ns, st.st_size, name)

    def take(self, path: Path, name: str, opener: Callable[..., Any] = FmuInstance) -> Any:
        """An instantiated FMU (not yet set up): a reset idle one, or opener(path, name)."""
        idle = self._idle.get(self._key(path, name))
        if idle:
            fmu = idle.pop()
            fmu.messages.clear()
            self.reused += 1
            return fmu
        return opener(path, name)

    def give(self, fmu: FmuInstance, clean: bool) -> None:
        """Back to the pool after a run: terminated (clean=True and no fatal status) instances
        are reset and kept; any other is freed."""
        try:
            key = self._key(fmu.path, fmu.name)
        except OSError:  # the file has gone: nobody will ask for it again
            clean = False
        if clean and not fmu.fatal and len(self._idle.get(key, ())) < self.limit:
            try:
                fmu.reset()
            except FmuError:
                pass
            else:
                self._idle.setdefault(key, []).append(fmu)
                return
        fmu.free()

    def clear(self) -> None:
        """Free every idle instance."""
        for idle in self._idle.values():
            for fmu in idle:
                fmu.free()
        self._idle.clear()
