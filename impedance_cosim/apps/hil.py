"""Hardware-in-the-loop style runs: swap a component's FMU (checked first), and the robot process
that stands in for the hardware behind the bridge plant FMU (bridge_model/, docs/hil.md).

- `replacement_problems` lists every way a replacement FMU does not fit a component: each SSD
  connector must exist with the same causality, type and unit; each parameter the active
  parameter set (and the --set overrides) give the component must exist as a parameter (with
  the same type, and unit when both have one).
- The robot process itself (`RobotServer`, `start_robot`) is in impedance_cosim/apps/robot.py;
  `robot` here checks its options and gets the session token (file or environment).
- CLI: `impedance-cosim swap` and `impedance-cosim robot` (add_parsers).
"""

from __future__ import annotations

import argparse
import ipaddress
import os
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from bridge_model import protocol
from impedance_cosim.apps.robot import MAX_STEP_RANGE, TICK_RANGE, Fault, RobotServer, check_range
from impedance_cosim.apps.robot_plant import PLANTS
from impedance_cosim.apps.robot_process import LISTENING, start_robot, stop_robot

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
    from impedance_cosim.cosim.fmus.files import FmuArchiveError, model_description
    from impedance_cosim.cosim.master.setup import connector_problems

    comp = system.component(component)
    fmu = Path(fmu)
    if not fmu.is_file():
        return [f"{component}: FMU {fmu} does not exist"]
    try:
        md = model_description(fmu)
    except FmuArchiveError as exc:
        return [f"{component}: {exc}"]
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


# --- CLI ----------------------------------------------------------------------------------------


def _cmd_robot(args: argparse.Namespace) -> int:
    """Serve until --duration ends (exit 0) or a signal comes: SIGINT and SIGTERM unwind as
    KeyboardInterrupt (cli.sigterm_raises) to _dispatch, which prints one line and returns
    128 + the signal's number (130, 143)."""
    from impedance_cosim.apps.options import parse_overrides

    realtime, tick, max_step, duration, faults, key = _robot_options(args)
    server = RobotServer(key, args.host, args.port, realtime, parse_overrides(args.set or []),
                         faults, tick=tick, max_step=max_step,
                         allow_remote=args.allow_remote, plant=args.plant)  # fmt: skip
    try:
        host, port = server.address
        print(f"{LISTENING} {host}:{port} ({server.mode})", flush=True)
        if not ipaddress.ip_address(host).is_loopback:  # only with --allow-remote
            print(f"robot: {host} is not a loopback address: every machine that can reach port"
                  f" {port} can send datagrams here (the token keeps them out; the traffic is not"
                  " encrypted: docs/hil-reference.md, Trust model)",
                  file=sys.stderr, flush=True)  # fmt: skip
        server.serve(duration)
    finally:
        server.close()
    return 0


def _robot_options(args: argparse.Namespace):
    """The robot's options, each checked (ValueError naming the option otherwise: main prints it
    as one line, exit 2; not CliError, which is another class when cli runs as __main__, as in
    the child start_robot starts); the session token's key from --token-file (created if
    missing) or the environment."""

    def number(name: str, text: str | None, low: float, high: float) -> float | None:
        if text is None:
            return None
        try:
            return check_range(name, float(text), low, high)
        except ValueError:
            raise ValueError(
                f"{name} must be a number from {low:g} to {high:g} (got {text!r})"
            ) from None

    tick = number("--tick", args.tick, *TICK_RANGE)
    max_step = number("--max-step", args.max_step, *MAX_STEP_RANGE)
    duration = number("--duration", args.duration, 1e-3, 1e7)
    try:
        port = int(args.port)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise ValueError(f"--port must be an integer from 0 to 65535 (got {args.port!r})")
    args.port = port
    faults = [Fault.parse(f) for f in args.fault or []]
    return args.realtime, tick, max_step, duration, faults, _session_key(args.token_file)


def _session_key(token_file: str | None) -> bytes:
    """The session token's MAC key: from the environment, or from token_file (created with a new
    token if it does not exist); ValueError otherwise."""
    env = os.environ.get(protocol.TOKEN_ENV)
    if token_file and env:
        raise ValueError(
            f"give the session token by --token-file or {protocol.TOKEN_ENV}, not both"
        )
    if env:
        return protocol.token_key(env, protocol.TOKEN_ENV)
    if not token_file:
        raise ValueError(f"no session token: give --token-file PATH (a new token is written there "
                         f"if it does not exist) or set {protocol.TOKEN_ENV}")  # fmt: skip
    key, created = protocol.token_file_key(token_file)  # the bridge's reader (never blocks)
    if created:
        print(f"robot: new session token written to {token_file} (mode 600)", file=sys.stderr)
    return key


def _cmd_swap(args: argparse.Namespace) -> int:
    from impedance_cosim.apps import options, run
    from impedance_cosim.apps.build_cmd import ensure_built
    from impedance_cosim.cosim.ssp.read import read_ssp

    replace = {}
    for item in args.replace:  # cheap checks first, before any build
        comp, sep, path = item.partition("=")
        if not sep or not comp or not path:
            raise options.CliError(f"--replace expects component=path/to/file.fmu (got {item!r})")
        replace[comp.strip()] = Path(path.strip())
    _check_archives(replace)
    overrides = options.parse_overrides(args.set or [])
    for name, value in overrides.items():  # a bridge's token file: refused before anything runs
        comp, _, var = name.partition(".")
        if var == "robot_token_file" and comp in replace:
            try:
                protocol.read_token_file(value)  # the bridge's own reader (never blocks)
            except ValueError as exc:
                raise options.CliError(f"--set {name}: {exc}") from None
    ssp = Path(args.ssp) if args.ssp else options.DEFAULT_SSP
    ensure_built(args, ssp)
    args.ssp = str(ssp)
    problems = []
    with read_ssp(ssp) as system:
        for comp, path in replace.items():
            problems += replacement_problems(system, comp, path, args.scenario, overrides)
    if problems:
        lines = "\n".join(f"  - {p}" for p in problems)
        raise options.CliError(
            f"the replacement does not fit the system ({len(problems)}):\n{lines}"
        )
    args.fmu_files = replace
    if not args.robot:
        _check_robot_given(replace, overrides)
    robot = None
    if args.robot:
        bridged = [c for c, p in replace.items() if _has_parameter(p, "robot_port")]
        if len(bridged) != 1:
            raise options.CliError("--robot needs exactly one replacement that is a bridge FMU")
        extra = [f"--set=plant.{s.split('.', 1)[1]}" for s in args.robot_set or []]
        extra += ["--plant", args.robot_plant]
        token = protocol.new_token()  # to the robot in its environment, to the bridge in-process
        robot, port = start_robot(token, args.robot == "realtime", extra)
        args.set = [*(args.set or []), f"{bridged[0]}.robot_port={port}",
                    f"{bridged[0]}.robot_token={token}"]  # fmt: skip
        print(f"robot process ({args.robot}) on port {port}", file=sys.stderr)
    try:
        return run.cmd_run(args)
    finally:
        if robot is not None:
            stop_robot(robot)


def _check_robot_given(replace: Mapping[str, Path], overrides: Mapping[str, str]) -> None:
    """A bridge replacement without --robot needs a robot started by the user, named by its
    token: say how to start one, or to let swap start it, before anything runs."""
    from impedance_cosim.apps import options

    for comp, path in replace.items():
        given = {f"{comp}.robot_token_file", f"{comp}.robot_token"} & set(overrides)
        if _has_parameter(path, "robot_port") and not given:
            raise options.CliError(
                f"{comp}={path} is a bridge to a robot process and none is given: use --robot"
                " lockstep (or realtime) to let swap start one, or start one (`impedance-cosim"
                f" robot --token-file PATH`) and add --set {comp}.robot_token_file=PATH"
            )


def _check_archives(replace: Mapping[str, Path]) -> None:
    """Each replacement FMU that exists is a safe archive (one line naming the file and the
    member, exit 2 otherwise), before anything is built, written or run."""
    from impedance_cosim.cosim.fmus.files import check_fmu_archive

    for path in replace.values():
        if path.is_file():
            check_fmu_archive(path, str(path))  # FmuArchiveError is a ValueError: exit 2


def _has_parameter(fmu: Path, name: str) -> bool:
    from impedance_cosim.cosim.fmus.files import model_description

    md = model_description(fmu)
    return any(v.name == name and v.causality == "parameter" for v in md.modelVariables)


def add_parsers(sub) -> None:
    """The `swap` and `robot` subcommands."""
    from impedance_cosim.apps.options import add_run_options

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
    p.add_argument(
        "--robot-plant",
        choices=PLANTS,
        default="ours",
        help="the plant the robot process runs (default ours; mujoco: MuJoCo's)",
    )
    add_run_options(p, out="results/swap")
    p.set_defaults(func=_cmd_swap)

    p = sub.add_parser(
        "robot",
        help="the stand-in for the robot hardware: the plant model behind the bridge protocol",
        description="Serve the plant over UDP for the bridge FMU (fmus/BridgePlant.fmu). Prints "
        f"'{LISTENING} HOST:PORT (mode)' first. Runs until killed (or --duration).",
    )
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to bind (default loopback; any other needs --allow-remote)",
    )
    p.add_argument("--allow-remote", action="store_true",
                   help="allow a --host other machines can reach ('' or 0.0.0.0: every "
                        "interface); see docs/hil-reference.md, Trust model")  # fmt: skip
    p.add_argument("--port", default="50400", help="UDP port (default 50400; 0: a free one)")
    p.add_argument("--plant", choices=PLANTS, default="ours",
                   help="the plant it runs: ours (default) or mujoco (MuJoCo's, as in"
                        " fmus/MujocoPlant.fmu; needs the mujoco package)")  # fmt: skip
    mode = p.add_mutually_exclusive_group()
    mode.add_argument("--lockstep", dest="realtime", action="store_false", default=False,
                      help="advance only on request (default; deterministic)")  # fmt: skip
    mode.add_argument("--realtime", dest="realtime", action="store_true",
                      help="integrate continuously against the wall clock")  # fmt: skip
    p.add_argument("--tick", default="0.001",
                   help="real time: integration tick [s] (default 0.001, 1e-5 to 0.1)")  # fmt: skip
    p.add_argument("--max-step", default="1.0",
                   help="longest STEP the robot takes [s] (default 1, at most 10)")  # fmt: skip
    p.add_argument("--token-file", default=None, metavar="PATH",
                   help="session token file (mode 600; created with a new token if missing); or "
                        f"set {protocol.TOKEN_ENV}")  # fmt: skip
    p.add_argument("--set", action="append", metavar="plant.VARIABLE=VALUE",
                   help="override a plant parameter sent by INIT (repeatable)")  # fmt: skip
    p.add_argument("--fault", action="append", metavar="KIND@SEQ[:ARG]",
                   help="fault at STEP SEQ: drop@N, late@N:SECONDS, seq@N, exit@N, "
                        "reset@N")  # fmt: skip
    p.add_argument("--duration", default=None, help="stop after this many seconds")
    p.set_defaults(func=_cmd_robot)
