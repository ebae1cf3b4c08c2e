"""Hardware-in-the-loop style runs: swap a component's FMU (checked first), and the robot process
that stands in for the hardware behind the bridge plant FMU (bridge_model/, docs/hil.md).

- `replacement_problems` lists every way a replacement FMU does not fit a component: each SSD
  connector must exist with the same causality, type and unit; each parameter the active
  parameter set (and the --set overrides) give the component must exist as a parameter (with
  the same type, and unit when both have one).
- `RobotServer` runs plant_model.model.PlantModel behind the bridge protocol
  (bridge_model/protocol.py) on UDP: in lock-step mode it steps exactly as the bridge asks (the
  same calls as the in-process plant: bit-identical results); in real-time mode it integrates
  against the wall clock in fixed ticks with the last torque held, and answers each request with
  its latest outputs. Faults can be injected for tests (`--fault`).
- CLI: `impedance-cosim swap` and `impedance-cosim robot` (add_parsers).
"""

from __future__ import annotations

import argparse
import os
import select
import socket
import subprocess
import sys
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from bridge_model import protocol

LISTENING = "robot: listening on"


# --- swap checks --------------------------------------------------------------------------------


def replacement_problems(
    system,
    component: str,
    fmu: Path,
    parameter_set: str | None = None,
    overrides: Mapping[str, Any] | None = None,
) -> list[str]:
    """Every difference between what the system needs of `component` and the FMU file (empty
    when it fits); see module docstring."""
    from fmpy import read_model_description

    from impedance_cosim.master import connector_problems

    comp = system.component(component)
    fmu = Path(fmu)
    if not fmu.is_file():
        return [f"{component}: FMU {fmu} does not exist"]
    try:
        md = read_model_description(str(fmu))
    except Exception as exc:
        return [f"{component}: cannot read {fmu.name}: {exc}"]
    variables = {v.name: v for v in md.modelVariables}
    problems = connector_problems(comp, variables, fmu.name)
    sets = system.parameter_sets
    name = parameter_set if parameter_set is not None else next(iter(sets), "")
    wanted = []
    for p in sets.get(name, []):
        c, _, var = p.name.partition(".")
        if c == component and var not in comp.connectors:  # connectors are checked above
            wanted.append((var, p.type, p.unit, f"parameter set {name!r}"))
    for key in overrides or {}:
        c, _, var = key.partition(".")
        if c == component:
            vector = [n for n in (f"{var}{i}" for i in (1, 2, 3)) if n in variables]
            for v in vector if var not in variables and vector else [var]:
                wanted.append((v, None, None, "--set"))
    for var, kind, unit, where in wanted:
        v = variables.get(var)
        what = f"{component}.{var} ({where})"
        if v is None:
            problems.append(f"{what}: no such parameter in {fmu.name}")
            continue
        if v.causality != "parameter":
            problems.append(f"{what}: is a {v.causality} in {fmu.name}, not a parameter")
        if kind and v.type != kind:
            problems.append(f"{what}: type {v.type} in the FMU, {kind} in the parameter set")
        if unit and v.unit and unit != v.unit:
            problems.append(f"{what}: unit {v.unit} in the FMU, {unit} in the parameter set")
    return problems


# --- the robot process --------------------------------------------------------------------------


@dataclass(frozen=True)
class Fault:
    """An injected fault at the STEP with sequence `seq`: drop (never answer), late (answer after
    `arg` seconds), seq (answer with the sequence number + 1000), exit (the process exits at
    once, without answering)."""

    kind: str
    seq: int
    arg: float = 0.0

    @classmethod
    def parse(cls, text: str) -> Fault:
        kind, _, rest = text.partition("@")
        seq, _, arg = rest.partition(":")
        if kind not in ("drop", "late", "seq", "exit") or not seq.isdigit():
            raise ValueError(f"--fault expects drop@N, late@N:SECONDS, seq@N or exit@N ({text!r})")
        return cls(kind, int(seq), float(arg or 0.0))


class RobotServer:
    """The plant behind the bridge protocol (see module docstring)."""

    def __init__(
        self,
        host: str = "127.0.0.1",
        port: int = 0,
        realtime: bool = False,
        overrides: Mapping[str, Any] | None = None,
        faults: list[Fault] | None = None,
        tick: float = 0.001,
        log=None,
    ) -> None:
        from plant_model.model import PlantModel

        self.model_class = PlantModel
        self.parameters = [v for v in PlantModel.variables() if v.causality == "parameter"]
        names = {v.name: v for v in self.parameters}
        self.overrides = {}
        for key, value in (overrides or {}).items():
            comp, _, var = key.partition(".")
            if comp != "plant" or var not in names:
                raise ValueError(f"the robot has no parameter {key!r} (write plant.<parameter>)")
            self.overrides[var] = _convert(names[var].type, value, key)
        self.realtime = realtime
        self.faults = {f.seq: f for f in faults or []}
        self.tick = tick
        self.log = log or (lambda text: print(f"robot: {text}", file=sys.stderr, flush=True))
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, port))
        self.address = self.sock.getsockname()
        self.plant = None
        self.cache: dict[Any, tuple[int, bytes]] = {}  # client -> (seq, reply) of its last request
        self.tau = (0.0, 0.0, 0.0)
        self.dropped = 0
        self.steps = 0

    @property
    def mode(self) -> str:
        return "real time" if self.realtime else "lock-step"

    def close(self) -> None:
        self.sock.close()

    def serve(self, duration: float | None = None) -> None:
        """Answer requests (for `duration` seconds, default forever)."""
        end = None if duration is None else time.perf_counter() + duration
        while end is None or time.perf_counter() < end:
            timeout = 0.2 if end is None else max(0.0, min(0.2, end - time.perf_counter()))
            if self.realtime and self.plant is not None:
                self._advance()
                timeout = min(timeout, max(0.0, self._next_tick() - time.perf_counter()))
            ready, _, _ = select.select([self.sock], [], [], timeout)
            if ready:
                raw, client = self.sock.recvfrom(65536)
                self._handle(raw, client)

    def _handle(self, raw: bytes, client) -> None:
        try:
            msg = protocol.Message(raw)
        except protocol.ProtocolError as exc:
            self.dropped += 1
            self.log(f"dropped a datagram from {client}: {exc}")
            return
        if msg.kind not in (protocol.INIT, protocol.STEP):
            self.dropped += 1
            return
        last = self.cache.get(client)
        if last and last[0] == msg.seq:
            self.sock.sendto(last[1], client)  # a resent request: the same answer, no new step
            return
        seq = msg.seq
        fault = self.faults.get(seq) if msg.kind == protocol.STEP else None
        if fault and fault.kind == "exit":
            self.log(f"fault injected: exiting at STEP {seq}")
            os._exit(3)
        if fault and fault.kind == "drop":
            self.log(f"fault injected: no reply to STEP {seq}")
            self.cache[client] = (seq, b"")
            return
        reply = self._init(msg) if msg.kind == protocol.INIT else self._step(msg)
        if fault and fault.kind == "late":
            self.log(f"fault injected: reply to STEP {seq} {fault.arg:g} s late")
            time.sleep(fault.arg)
        if fault and fault.kind == "seq":
            self.log(f"fault injected: reply to STEP {seq} with sequence {seq + 1000}")
            reply = reply[:8] + (seq + 1000).to_bytes(4, "little") + reply[12:]
        self.cache[client] = (seq, reply)
        self.sock.sendto(reply, client)

    def _init(self, msg: protocol.Message) -> bytes:
        from impedance_cosim.fmi.model import ModelError

        if len(msg.values) != len(self.parameters):
            n, want = len(msg.values), len(self.parameters)
            text = f"INIT carries {n} parameters, the plant has {want}"
            return protocol.pack(protocol.ERROR, msg.seq, msg.t, 0.0, text=text)
        params = {
            v.name: _convert(v.type, x, v.name)
            for v, x in zip(self.parameters, msg.values, strict=True)
        }
        params.update(self.overrides)
        try:
            self.plant = self.model_class(params, msg.t, None)
        except ModelError as exc:
            self.plant = None
            return protocol.pack(protocol.ERROR, msg.seq, msg.t, 0.0, text=str(exc))
        self.tau = (0.0, 0.0, 0.0)
        self.t_sim0, self.k = msg.t, 0
        self.t_wall0 = time.perf_counter()
        self.steps = 0
        self.log(f"INIT ({self.mode}) at t={msg.t:g}")
        return self._reply(protocol.INIT_REPLY, msg)

    def _step(self, msg: protocol.Message) -> bytes:
        from impedance_cosim.fmi.model import ModelError

        if self.plant is None:
            text = "no plant: INIT first"
            return protocol.pack(protocol.ERROR, msg.seq, msg.t, msg.h, text=text)
        try:
            if self.realtime:
                self._advance()
                self.tau = tuple(msg.values)
            else:
                self.plant.do_step(msg.t, msg.h, tuple(msg.values))
        except ModelError as exc:
            return protocol.pack(protocol.ERROR, msg.seq, msg.t, msg.h, text=str(exc))
        self.steps += 1
        return self._reply(protocol.STEP_REPLY, msg)

    def _reply(self, kind: int, msg: protocol.Message) -> bytes:
        return protocol.pack(kind, msg.seq, self.plant.t, msg.h, self.plant.outputs(),
                             echo_ns=msg.stamp_ns)  # fmt: skip

    # real time: the plant advances in ticks of `tick` seconds of wall-clock time
    def _next_tick(self) -> float:
        return self.t_wall0 + (self.k + 1) * self.tick

    def _advance(self) -> None:
        from impedance_cosim.fmi.model import ModelError

        while time.perf_counter() >= self._next_tick():
            try:
                self.plant.do_step(self.t_sim0 + self.k * self.tick, self.tick, self.tau)
            except ModelError as exc:
                self.log(f"the plant failed at t={self.plant.t:g}: {exc}; stopped")
                self.plant = None
                return
            self.k += 1


def _convert(kind: str, value: Any, name: str) -> Any:
    from impedance_cosim.fmu import fmi_value

    if kind in ("Integer", "Boolean") and isinstance(value, float):
        value = int(value)
    return fmi_value(kind, value, name)


def start_robot(
    realtime: bool = False, extra: list[str] | None = None, timeout: float = 20.0
) -> tuple[subprocess.Popen, int]:
    """Start `impedance-cosim robot` on a free loopback port as a child process; returns it and
    its port (read from its first line). The caller must kill it."""
    cmd = [sys.executable, "-m", "impedance_cosim.cli", "robot", "--port", "0"]
    cmd += ["--realtime" if realtime else "--lockstep", *(extra or [])]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    line = proc.stdout.readline() if ready else ""
    if LISTENING not in line:
        proc.kill()
        proc.wait()
        raise RuntimeError(f"the robot process did not start (got {line!r})")
    return proc, int(line.split()[3].rsplit(":", 1)[1])


def stop_robot(proc: subprocess.Popen) -> None:
    """Kill a robot process started by start_robot and reap it."""
    if proc.poll() is None:
        proc.kill()
    proc.wait(timeout=10)
    if proc.stdout:
        proc.stdout.close()


# --- CLI ----------------------------------------------------------------------------------------


def _cmd_robot(args: argparse.Namespace) -> int:
    from impedance_cosim.cli import parse_overrides

    faults = [Fault.parse(f) for f in args.fault or []]
    server = RobotServer(args.host, args.port, args.realtime, parse_overrides(args.set or []),
                         faults, tick=args.tick)  # fmt: skip
    host, port = server.address
    print(f"{LISTENING} {host}:{port} ({server.mode})", flush=True)
    try:
        server.serve(args.duration)
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    return 0


def _cmd_swap(args: argparse.Namespace) -> int:
    from impedance_cosim import cli
    from impedance_cosim.ssp import read_ssp

    ssp = Path(args.ssp) if args.ssp else cli.DEFAULT_SSP
    if not args.ssp and cli._stale(ssp):
        print("building the FMUs and the system archive ...", file=sys.stderr)
        cli._cmd_build(argparse.Namespace(out=str(ssp.parent), only=None))
    args.ssp = str(ssp)
    replace = {}
    for item in args.replace:
        comp, sep, path = item.partition("=")
        if not sep or not comp or not path:
            raise cli.CliError(f"--replace expects component=path/to/file.fmu (got {item!r})")
        replace[comp.strip()] = Path(path.strip())
    overrides = cli.parse_overrides(args.set or [])
    system = read_ssp(ssp)
    problems = []
    for comp, path in replace.items():
        problems += replacement_problems(system, comp, path, args.scenario, overrides)
    if problems:
        lines = "\n".join(f"  - {p}" for p in problems)
        raise cli.CliError(f"the replacement does not fit the system ({len(problems)}):\n{lines}")
    args.fmu_files = replace
    robot = None
    if args.robot:
        bridged = [c for c, p in replace.items() if _has_parameter(p, "robot_port")]
        if len(bridged) != 1:
            raise cli.CliError("--robot needs exactly one replacement that is a bridge FMU")
        extra = [f"--set=plant.{s.split('.', 1)[1]}" for s in args.robot_set or []]
        robot, port = start_robot(args.robot == "realtime", extra)
        args.set = [*(args.set or []), f"{bridged[0]}.robot_port={port}"]
        print(f"robot process ({args.robot}) on port {port}", file=sys.stderr)
    try:
        return cli._cmd_run(args)
    finally:
        if robot is not None:
            stop_robot(robot)


def _has_parameter(fmu: Path, name: str) -> bool:
    from fmpy import read_model_description

    md = read_model_description(str(fmu))
    return any(v.name == name and v.causality == "parameter" for v in md.modelVariables)


def add_parsers(sub) -> None:
    """The `swap` and `robot` subcommands."""
    from impedance_cosim.cli import add_run_options

    p = sub.add_parser(
        "swap",
        help="run the system with a component replaced by another FMU (checked first)",
        description="Run like `run`, with one or more components replaced: --replace "
        "plant=fmus/native/PumaPlant.fmu. The replacement must have every connector the SSD "
        "wires (same causality, type, unit) and the parameters the parameter set gives it.",
    )
    p.add_argument("--replace", action="append", required=True, metavar="COMPONENT=FMU",
                   help="replace a component's FMU (repeatable)")  # fmt: skip
    p.add_argument("--robot", choices=["lockstep", "realtime"], default=None,
                   help="start a robot process for the bridge FMU on a free port (and set its "
                        "robot_port); killed after the run")  # fmt: skip
    p.add_argument("--robot-set", action="append", metavar="plant.VARIABLE=VALUE",
                   help="a parameter the robot process overrides (model mismatch)")  # fmt: skip
    add_run_options(p, out="results/swap")
    p.set_defaults(func=_cmd_swap)

    p = sub.add_parser(
        "robot",
        help="the stand-in for the robot hardware: the plant model behind the bridge protocol",
        description="Serve the plant over UDP for the bridge FMU (fmus/BridgePlant.fmu). Prints "
        f"'{LISTENING} HOST:PORT (mode)' first. Runs until killed (or --duration).",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default loopback)")
    p.add_argument("--port", type=int, default=50400, help="UDP port (0: a free one)")
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="realtime", action="store_false", default=False,
                      help="advance only on request (default; deterministic)")  # fmt: skip
    mode.add_argument("--realtime", dest="realtime", action="store_true",
                      help="integrate continuously against the wall clock")  # fmt: skip
    p.add_argument("--tick", type=float, default=0.001,
                   help="real time: integration tick [s] (default 0.001)")  # fmt: skip
    p.add_argument("--set", action="append", metavar="plant.VARIABLE=VALUE",
                   help="override a plant parameter sent by INIT (repeatable)")  # fmt: skip
    p.add_argument("--fault", action="append", metavar="KIND@SEQ[:ARG]",
                   help="fault at STEP SEQ: drop@N, late@N:SECONDS, seq@N, exit@N")  # fmt: skip
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.set_defaults(func=_cmd_robot)
