"""``sitl`` command line: run the bundled SITL on a mission.

``sitl MISSION.yaml [--ports px4|legacy] [--listen URL] [--gcs URL|none] [--out udpout:127.0.0.1:14550 ...]
[--control-out URL ...] [--controller SYSID/COMPID[@LINK] ...] [--signing-key FILE]
[--max-clients 8] [--client-timeout 10] [--lockstep] [--speed 1] [--seed N]
[--physics-hz 1000] [--sensor-hz 250] [--start X,Y[,YAW_DEG]]``

``--start`` sets the vehicle down at ENU (X, Y) metres of the map frame (z
from the DEM), heading YAW_DEG (ENU: body x axis from east, counter-clockwise,
default 0), like a user placing the drone at the launch point. Without it the
mission's ``sim.start_enu_m`` or a free mid-corridor cell is used.

Links and control (``sitl.auth``): ``--listen`` and every ``--control-out``
are control links; ``--out`` links are telemetry-only (a ground station
that only watches). Control messages are accepted from the controllers
(``--controller``, repeatable, replaces the defaults 1/191, 255/190,
245/190 and 255/230; ``@LINK`` restricts one to that link's connection
string) on control links; read-only requests from anyone. ``--signing-key
FILE`` (32 raw bytes, or a passphrase as MAVProxy's ``signing setup``)
signs everything sent and requires signed control. A ``udpin`` link serves
at most ``--max-clients`` peers, dropping those silent for
``--client-timeout`` seconds (wall clock). ``--stats FILE`` writes, on
exit, who controlled the vehicle and what was ignored (JSON; per UDP link
also ``lockstep_spins``, the lockstep waits that busy-polled, and
``lockstep_spin_hits``, those whose answer came within the spin:
``mavcore.link.pipe.AdaptiveSpin``).

Loopback addresses by default (a ``udpout`` link is connected to its
peer, so nobody else can write to it). Bad input (mission file, maps,
connection string, a port in use, rates, a start point off the map, a key
file) ends with one line on stderr and exit code 2. SIGINT and
SIGTERM stop the loop and close the sockets (exit 0). Once the links are
open the SITL prints one line ``sitl: ready <listen>`` on stdout (the
readiness marker ``sitl.api.SitlProcess`` waits for). With the environment
variable ``SITL_PROFILE=FILE`` the main loop runs under cProfile and the
statistics are written to FILE on exit (a developer aid).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
from pathlib import Path

from mavcore.errors import InputError
from mavcore.logs import add_verbosity, configure

READY_MARKER = "sitl: ready"
#: Port conventions (``--ports``): (main link, ground-station link or None).
PORTS = {"px4": ("udpout:127.0.0.1:14540", "udpout:127.0.0.1:14550"), "legacy": ("udpin:127.0.0.1:14540", None)}
#: Fastest real-time factor asked for (beyond it, "as fast as possible" is --speed 0).
MAX_SPEED = 1000.0


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sitl", description=__doc__.splitlines()[0])
    p.add_argument("mission", help="mission YAML (its maps give the terrain and the vine rows)")
    p.add_argument("--ports", choices=("px4", "legacy"), default="px4",
                   help="port convention: px4 (default): the vehicle sends to the companion on 14540 "
                        f"({PORTS['px4'][0]}) and to a ground station on 14550 ({PORTS['px4'][1]}, control "
                        f"allowed), as PX4's SITL; legacy: the SITL listens on {PORTS['legacy'][0]}, no GCS link")
    p.add_argument("--listen", default=None,
                   help="main MAVLink link, pymavlink syntax (default: the --ports convention's)")
    p.add_argument("--gcs", default=None, metavar="URL|none",
                   help="ground-station link, carries control (default: the --ports convention's; none: no link)")
    p.add_argument("--out", action="append", default=[], metavar="URL",
                   help="extra telemetry-only MAVLink link, e.g. udpout:127.0.0.1:14550 (repeatable)")
    p.add_argument("--control-out", action="append", default=[], metavar="URL",
                   help="extra MAVLink link that may carry control from the controllers (repeatable)")
    p.add_argument("--controller", action="append", default=None, metavar="SYSID/COMPID[@LINK]",
                   help="who may control the vehicle (repeatable; replaces the defaults "
                        "1/191 255/190 245/190 255/230; @LINK: only on that control link)")
    p.add_argument("--signing-key", default=None, metavar="FILE",
                   help="MAVLink 2 signing key file: 32 raw bytes, or a passphrase (SHA-256, as MAVProxy)")
    p.add_argument("--max-clients", type=int, default=8, metavar="N",
                   help="peers a udpin link serves at most (default %(default)s)")
    p.add_argument("--client-timeout", type=float, default=10.0, metavar="S",
                   help="drop a udpin peer silent for S wall-clock seconds (default %(default)s)")
    p.add_argument("--stats", default=None, metavar="FILE",
                   help="on exit, write link statistics as JSON (control accepted by source, ignored by reason)")
    p.add_argument("--autopilot", choices=("px4", "ardupilot"), default=None,
                   help="flight stack to speak as: modes, parameters, take-off and failsafe rules "
                        "(default: the mission's sim.autopilot, else px4)")
    p.add_argument("--lockstep", action="store_true",
                   help="lockstep with the peer that answers HIGHRES_IMU with HIL_ACTUATOR_CONTROLS")
    p.add_argument("--speed", type=float, default=1.0,
                   help="real-time factor when free-running, 0 = as fast as possible (default 1)")
    p.add_argument("--seed", type=int, default=None, help="random seed (default: the mission's sim.seed)")
    p.add_argument("--physics-hz", type=int, default=1000, help="physics rate (default %(default)s)")
    p.add_argument("--sensor-hz", type=int, default=250, help="sensor frame rate (default %(default)s)")
    p.add_argument("--start", default=None, metavar="X,Y[,YAW_DEG]",
                   help="launch position, ENU metres on the map, and heading, ENU degrees from east "
                        "(default: the mission's sim.start_enu_m, else a free mid-corridor cell); "
                        "'-': read it as one line from stdin")
    add_verbosity(p)
    return p


def port_links(ports: str, listen: str | None, gcs: str | None) -> tuple[str, str | None]:
    """(main link, ground-station link or None) of a port convention
    (``--ports``), with ``--listen``/``--gcs`` given (None: the convention's;
    ``--gcs none``: no ground-station link)."""
    listen_default, gcs_default = PORTS[ports]
    gcs = gcs_default if gcs is None else (None if gcs == "none" else gcs)
    return (listen_default if listen is None else listen), gcs


def parse_start(text: str) -> tuple[float, float, float]:
    """``"X,Y[,YAW_DEG]"`` -> (x_m, y_m, yaw_deg) (ENU; yaw 0 when omitted).

    Raises
    ------
    InputError
        Not two or three finite numbers.
    """
    parts = [p.strip() for p in str(text).split(",")]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        vals = []
    if len(vals) not in (2, 3) or not all(math.isfinite(v) for v in vals):
        raise InputError(f"--start {text}", "expected X,Y or X,Y,YAW_DEG (finite numbers: ENU metres, degrees)")
    return (vals[0], vals[1], vals[2] if len(vals) == 3 else 0.0)


def start_off_map(world, x_m: float, y_m: float) -> str | None:
    """Why (x, y) (ENU m) is not a place to set the vehicle down, or None:
    outside the occupancy grid or where the DEM gives no height."""
    grid = world.grid
    if grid is not None:
        r, c = grid.world_to_cell(x_m, y_m)
        rows, cols = grid.shape
        if not (-0.5 <= float(r) <= rows - 0.5 and -0.5 <= float(c) <= cols - 0.5):
            x0, y0 = grid.cell_to_world(-0.5, -0.5)
            x1, y1 = grid.cell_to_world(rows - 0.5, cols - 0.5)
            return (f"({x_m:g}, {y_m:g}) is off the map (x {min(x0, x1):g}..{max(x0, x1):g}, "
                    f"y {min(y0, y1):g}..{max(y0, y1):g} m)")
    dem = getattr(world.terrain, "dem", None)
    if dem is not None and not bool(dem.covers(x_m, y_m)):
        return f"({x_m:g}, {y_m:g}) is outside the elevation model"
    return None


def _check_url(url: str, what: str) -> None:
    prefixes = ("udpin:", "udpout:", "udp:", "udpbcast:", "tcp:", "tcpin:")
    if url.startswith(prefixes):
        rest = url.split(":", 1)[1]
        host, sep, port = rest.rpartition(":")
        if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise InputError(what, f"bad connection string {url!r} (expected e.g. udpin:127.0.0.1:14540)")
        return
    if url.startswith("/dev/") or url.upper().startswith("COM"):
        return   # serial device
    raise InputError(what, f"bad connection string {url!r} (expected udpin:/udpout:/tcp:/tcpin:HOST:PORT)")


def parse_controllers(texts, control_links) -> tuple | None:
    """``--controller`` values -> tuple of ``sitl.auth.Controller`` (None: the defaults).

    Raises
    ------
    InputError
        Malformed, ids out of range, or ``@LINK`` not a control link.
    """
    from .auth import parse_controller

    if texts is None:
        return None
    out = []
    for t in texts:
        try:
            c = parse_controller(t)
        except ValueError as exc:
            raise InputError(f"--controller {t}", str(exc)) from None
        if c.link is not None and c.link not in control_links:
            raise InputError(f"--controller {t}", f"{c.link!r} is not a control link (--listen or --control-out: "
                                                  f"{', '.join(control_links)})")
        out.append(c)
    return tuple(out)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    configure(args.verbose, args.quiet)
    try:
        return _run(args)
    except InputError as exc:
        print(f"sitl: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0


def _run(args) -> int:
    # Imports here so that ``sitl --help`` stays instant.
    from mavcore.mission import load_mission

    from .server import ServerConfig, SitlServer

    args.listen, gcs = port_links(args.ports, args.listen, args.gcs)
    if gcs is not None:
        _check_url(gcs, "--gcs")
        args.control_out = [*args.control_out, gcs]
    _check_url(args.listen, "--listen")
    for u in args.out:
        _check_url(u, "--out")
    for u in args.control_out:
        _check_url(u, "--control-out")
    urls = [args.listen, *args.out, *args.control_out]
    if len(set(urls)) != len(urls):
        raise InputError("--listen/--out/--control-out", "the same link is given twice")
    controllers = parse_controllers(args.controller, [args.listen, *args.control_out])
    if not (math.isfinite(args.speed) and 0 <= args.speed <= MAX_SPEED):
        raise InputError(f"--speed {args.speed}", f"must be a number in [0, {MAX_SPEED:g}] (0: as fast as possible)")
    if not 1 <= args.max_clients <= 1024:
        raise InputError(f"--max-clients {args.max_clients}", "must be in [1, 1024]")
    if not (math.isfinite(args.client_timeout) and 0.1 <= args.client_timeout <= 3600):
        raise InputError(f"--client-timeout {args.client_timeout}", "must be in [0.1, 3600] seconds")
    key = None
    if args.signing_key is not None:
        from mavcore.link.signing import load_signing_key
        key = load_signing_key(args.signing_key)
    if args.stats is not None:
        sp = Path(args.stats)
        if sp.is_dir() or not sp.parent.is_dir():
            raise InputError(f"--stats {args.stats}", "is a directory" if sp.is_dir()
                             else f"directory {sp.parent} does not exist")
    if args.physics_hz <= 0 or args.sensor_hz <= 0 or args.physics_hz % args.sensor_hz:
        raise InputError("--physics-hz/--sensor-hz", "physics rate must be a positive multiple of the sensor rate")
    if 1_000_000 % args.sensor_hz:
        raise InputError("--sensor-hz", "must divide 1000000 (whole-microsecond frames)")
    if args.start not in (None, "-"):
        parse_start(args.start)          # bad value: fail before loading anything
    mission = load_mission(args.mission)
    if args.start == "-":   # the launcher sends the pose now (sitl.api.SitlProcess start="later")
        args.start = sys.stdin.readline().strip()
    start = None if args.start is None else parse_start(args.start)
    config = ServerConfig(listen=args.listen, outs=tuple(args.out), lockstep=args.lockstep,
                          speed=args.speed, seed=args.seed, physics_hz=args.physics_hz,
                          sensor_hz=args.sensor_hz, start=start, control_outs=tuple(args.control_out),
                          controllers=controllers, signing_key=key, max_clients=args.max_clients,
                          client_timeout_s=args.client_timeout, autopilot=args.autopilot)
    try:
        server = SitlServer(mission, config)
    except InputError:
        raise
    except ValueError as exc:   # e.g. a sim value outside a parameter's range
        raise InputError(args.mission, str(exc)) from None
    xy = start[:2] if start is not None else mission.sim.start_enu_m
    if xy is not None:
        why = start_off_map(server.vehicle.sim.world, float(xy[0]), float(xy[1]))
        if why:
            raise InputError(f"--start {args.start}" if start is not None else f"{args.mission}: key 'sim.start_enu_m'",
                             why)
    try:
        server.open()
    except InputError:
        raise
    except (OSError, ValueError) as exc:
        raise InputError("--listen/--out", f"cannot open link: {exc}") from None

    def _stop(signum, frame):
        server.stop()

    signal.signal(signal.SIGINT, _stop)
    signal.signal(signal.SIGTERM, _stop)
    print(f"{READY_MARKER} {args.listen}", flush=True)
    profile_path = os.environ.get("SITL_PROFILE")   # developer aid: cProfile the main loop
    profiler = None
    if profile_path:
        import cProfile
        profiler = cProfile.Profile()
        profiler.enable()
    try:
        server.run()
    finally:
        report = server.link_report() if args.stats is not None else None
        server.close()
        if report is not None:
            tmp = Path(args.stats + ".part")
            tmp.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
            os.replace(tmp, args.stats)
        if profiler is not None:
            profiler.disable()
            profiler.dump_stats(profile_path)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
