"""``sitl`` command line: run the bundled SITL on a mission.

``sitl MISSION.yaml [--listen udpin:127.0.0.1:14540] [--out udpout:127.0.0.1:14550 ...]
[--lockstep] [--speed 1] [--seed N] [--physics-hz 1000] [--sensor-hz 250] [--start X,Y[,YAW_DEG]]``

``--start`` sets the vehicle down at ENU (X, Y) metres of the map frame (z
from the DEM), heading YAW_DEG (ENU: body x axis from east, counter-clockwise,
default 0), like a user placing the drone at the launch point. Without it the
mission's ``sim.start_enu_m`` or a free mid-corridor cell is used.

Loopback addresses by default. Bad input (mission file, maps, connection
string, rates) ends with one line on stderr and exit code 2. SIGINT and
SIGTERM stop the loop and close the sockets (exit 0). Once the links are
open the SITL prints one line ``sitl: ready <listen>`` on stdout (the
readiness marker ``sitl.api.SitlProcess`` waits for). With the environment
variable ``SITL_PROFILE=FILE`` the main loop runs under cProfile and the
statistics are written to FILE on exit (a developer aid).
"""

from __future__ import annotations

import argparse
import math
import os
import signal
import sys

from companion.errors import InputError

READY_MARKER = "sitl: ready"


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sitl", description=__doc__.splitlines()[0])
    p.add_argument("mission", help="mission YAML (its maps give the terrain and the vine rows)")
    p.add_argument("--listen", default="udpin:127.0.0.1:14540",
                   help="main MAVLink link, pymavlink syntax (default %(default)s)")
    p.add_argument("--out", action="append", default=[], metavar="URL",
                   help="extra MAVLink link, e.g. udpout:127.0.0.1:14550 (repeatable)")
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
    return p


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


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return _run(args)
    except InputError as exc:
        print(f"sitl: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 0


def _run(args) -> int:
    # Imports here so that ``sitl --help`` stays instant.
    from companion.mission import load_mission

    from .server import ServerConfig, SitlServer

    _check_url(args.listen, "--listen")
    for u in args.out:
        _check_url(u, "--out")
    if not args.speed >= 0:
        raise InputError("--speed", "must be >= 0 (0: as fast as possible)")
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
                          sensor_hz=args.sensor_hz, start=start)
    try:
        server = SitlServer(mission, config)
    except ValueError as exc:   # e.g. a sim value outside a parameter's range
        raise InputError(args.mission, str(exc)) from None
    try:
        server.open()
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
        server.close()
        if profiler is not None:
            profiler.disable()
            profiler.dump_stats(profile_path)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
