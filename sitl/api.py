"""Start the SITL from Python, for tests and the demo.

``SitlThread`` runs the server loop in a background thread of this process
(cheap, shares the GIL with the caller); ``SitlProcess`` runs ``python -m
sitl`` as a subprocess (its own interpreter: ``companion demo --transport
udp``); ``SitlInProcess`` runs no loop of its own: its one link is the
in-process transport (``inproc:NAME``, ``mavcore.link.pipe.MemoryPipe``) and the
companion's waits step it (``companion demo --transport inproc``, campaigns).
All are context managers with ``start()``/``stop()``; ``start()`` returns
once the links are open (readiness), so a client may connect at once.

Example
-------
>>> with SitlProcess("missions/flat-rectangle/mission.yaml",
...                  listen=f"udpin:127.0.0.1:{free_udp_port()}", lockstep=True, speed=0) as sitl:
...     ...   # connect to sitl.listen
"""

from __future__ import annotations

import math
import os
import select
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from mavcore.errors import LinkError


def free_udp_port(host: str = "127.0.0.1") -> int:
    """A UDP port that was free a moment ago on ``host``."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def peer_url(listen: str) -> str:
    """The connection string a client uses to reach a SITL listening on
    ``listen`` (``udpin:H:P`` -> ``udpout:H:P``, ``tcpin:H:P`` -> ``tcp:H:P``)."""
    if listen.startswith("udpin:"):
        return "udpout:" + listen[len("udpin:"):]
    if listen.startswith("tcpin:"):
        return "tcp:" + listen[len("tcpin:"):]
    return listen


def _check_start(start):
    """``start`` as (x_m, y_m, yaw_deg) floats, or None; ValueError if malformed."""
    if start is None:
        return None
    st = tuple(float(v) for v in start)
    if len(st) == 2:
        st += (0.0,)
    if len(st) != 3 or not all(math.isfinite(v) for v in st):
        raise ValueError("start must be (x_m, y_m[, yaw_deg]), finite numbers")
    return st


class _SitlOptions:
    """What both ways of running the SITL share: the mission and the options
    of the ``sitl`` command line (see ``SitlThread``)."""

    def __init__(self, mission_path, *, listen: str | None = None, outs=(), lockstep: bool = False,
                 speed: float = 1.0, seed: int | None = None, physics_hz: int = 1000,
                 sensor_hz: int = 250, control_outs=(), signing_key_file=None, max_clients: int = 8,
                 client_timeout_s: float = 10.0, stats_file=None, controllers=None,
                 autopilot: str | None = None) -> None:
        self.mission_path = Path(mission_path)
        self.listen = listen or f"udpin:127.0.0.1:{free_udp_port()}"
        self.outs = tuple(outs)
        self.control_outs = tuple(control_outs)
        self.signing_key_file = None if signing_key_file is None else str(signing_key_file)
        self.max_clients = int(max_clients)
        self.client_timeout_s = float(client_timeout_s)
        self.stats_file = None if stats_file is None else str(stats_file)
        self.controllers = None if controllers is None else tuple(str(c) for c in controllers)
        self.lockstep = lockstep
        self.speed = speed
        self.seed = seed
        self.physics_hz = physics_hz
        self.sensor_hz = sensor_hz
        self.autopilot = autopilot

    def _server_inputs(self):
        """What an in-process server is built from: the mission, the signing key (or
        None) and the allowed controllers (or None), read from the options' files."""
        from mavcore.mission import load_mission

        mission = load_mission(self.mission_path)
        key = None
        if self.signing_key_file is not None:
            from mavcore.link.signing import load_signing_key
            key = load_signing_key(self.signing_key_file)
        controllers = None
        if self.controllers is not None:
            from .auth import parse_controller
            controllers = tuple(parse_controller(c) for c in self.controllers)
        return mission, key, controllers

    @property
    def url(self) -> str:
        """Connection string for a client."""
        return peer_url(self.listen)


class SitlThread(_SitlOptions):
    """The SITL in a daemon thread of this process.

    Parameters
    ----------
    mission_path : str or Path
    listen : str
        Main link (default: a free loopback UDP port).
    outs : sequence of str
        Telemetry-only links.
    control_outs : sequence of str
        Extra links that carry control too (``sitl --control-out``).
    signing_key_file : str or Path, optional
        MAVLink 2 signing key file (``sitl --signing-key``).
    max_clients, client_timeout_s
        ``sitl --max-clients``, ``--client-timeout``.
    stats_file : str or Path, optional
        ``sitl --stats`` (``SitlProcess`` only; a ``SitlThread``'s server is at hand).
    controllers : sequence of str, optional
        ``sitl --controller`` values (``SYSID/COMPID[@LINK]``); None: the defaults.
    autopilot : str, optional
        ``sitl --autopilot`` ("px4", "ardupilot"); None: the mission's ``sim.autopilot``.
    lockstep : bool
    speed : float
        Real-time factor when free-running (0: as fast as possible).
    seed : int or None
    physics_hz, sensor_hz : int
    start : (x_m, y_m) or (x_m, y_m, yaw_deg), optional
        Launch position on the map (ENU metres, z from the DEM) and heading
        (ENU degrees from east, counter-clockwise); ``sitl --start``.
    """

    def __init__(self, mission_path, *, start=None, **options) -> None:
        super().__init__(mission_path, **options)
        self.start_pose = _check_start(start)
        self.server = None
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    def start(self) -> "SitlThread":
        from .server import ServerConfig, SitlServer

        mission, key, controllers = self._server_inputs()
        cfg = ServerConfig(listen=self.listen, outs=self.outs, lockstep=self.lockstep, speed=self.speed,
                           seed=self.seed, physics_hz=self.physics_hz, sensor_hz=self.sensor_hz,
                           start=self.start_pose, spin=False, control_outs=self.control_outs, signing_key=key,
                           max_clients=self.max_clients, client_timeout_s=self.client_timeout_s,
                           controllers=controllers, autopilot=self.autopilot)
        self.server = SitlServer(mission, cfg)
        self.server.open()   # readiness: the sockets exist when start() returns

        def run():
            try:
                self.server.run()
            except BaseException as exc:   # surfaced by stop()
                self.error = exc

        self._thread = threading.Thread(target=run, name="sitl", daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        if self.server is None:
            return
        self.server.stop()
        if self._thread is not None:
            self._thread.join(timeout_s)
        self.server.close()
        self.server = None
        if self.error is not None:
            err, self.error = self.error, None
            raise RuntimeError("the SITL thread failed") from err

    def __enter__(self) -> "SitlThread":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


class SitlInProcess(_SitlOptions):
    """The SITL in this process, stepped by its peer (``SitlServer.service``):
    the same server, codec, framing, signing and lockstep as ``SitlProcess``,
    with the datagrams passed through memory (``mavcore.link.pipe``) instead of UDP.
    Always lockstep; one link, ``inproc:NAME`` (``url``), for one peer in
    this process (``companion.link.Connection``), whose waits run the vehicle.

    Same parameters as ``SitlThread`` except the links (``listen``, ``outs``,
    ``control_outs``, ``max_clients``, ``client_timeout_s``) and ``lockstep``.
    ``start="later"``, ``launch()``, ``set_start()``, ``wait_ready()`` as
    ``SitlProcess``'s, so a caller can use either.
    """

    _count = 0
    _count_lock = threading.Lock()

    def __init__(self, mission_path, *, start=None, **options) -> None:
        for k in ("listen", "outs", "control_outs", "lockstep", "max_clients", "client_timeout_s"):
            if k in options:
                raise TypeError(f"SitlInProcess has no {k!r}: its one link is inproc:NAME, lockstep")
        with SitlInProcess._count_lock:
            SitlInProcess._count += 1
            name = f"sitl-{os.getpid()}-{SitlInProcess._count}"
        super().__init__(mission_path, listen="inproc:" + name, lockstep=True, **options)
        self.deferred = isinstance(start, str) and start == "later"
        self.start_pose = None if self.deferred else _check_start(start)
        self.server = None

    def launch(self) -> "SitlInProcess":
        return self

    def set_start(self, start) -> None:
        self.start_pose = _check_start(start)

    def start(self) -> "SitlInProcess":
        return self.wait_ready()

    def wait_ready(self) -> "SitlInProcess":
        """Build the server and register its link (no thread, no socket)."""
        from .server import ServerConfig, SitlServer

        if self.server is not None:
            return self
        mission, key, controllers = self._server_inputs()
        cfg = ServerConfig(listen=self.listen, lockstep=True, speed=0.0, seed=self.seed,
                           physics_hz=self.physics_hz, sensor_hz=self.sensor_hz, start=self.start_pose,
                           spin=False, signing_key=key, controllers=controllers, autopilot=self.autopilot)
        server = SitlServer(mission, cfg)
        server.open()
        self.server = server
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        server, self.server = self.server, None
        if server is not None:
            server.stop()
            if self.stats_file is not None:
                import json
                Path(self.stats_file).write_text(json.dumps(server.link_report(), indent=2) + "\n",
                                                 encoding="utf-8")
            server.close()

    def __enter__(self) -> "SitlInProcess":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


class SitlProcess(_SitlOptions):
    """The SITL as a ``python -m sitl`` subprocess (same parameters as
    ``SitlThread``). ``start()`` waits for the ready line; ``stop()`` sends
    SIGTERM (then SIGKILL after ``timeout_s``).

    ``start="later"`` lets a caller launch the process before it knows the
    launch pose (the process imports its modules meanwhile): ``launch()``,
    then ``set_start((x, y, yaw_deg))`` (``sitl --start -`` reads it from
    stdin), then ``wait_ready()``.
    """

    READY_TIMEOUT_S = 30.0

    def __init__(self, mission_path, *, python: str = sys.executable, start=None, **options) -> None:
        super().__init__(mission_path, **options)
        self.python = python
        self.deferred = isinstance(start, str) and start == "later"
        self.start_pose = None if self.deferred else _check_start(start)
        self.proc: subprocess.Popen | None = None
        self._stderr = None

    def command(self) -> list[str]:
        cmd = [self.python, "-m", "sitl", str(self.mission_path), "--listen", self.listen, "--gcs", "none",
               "--speed", repr(float(self.speed)), "--physics-hz", str(self.physics_hz),
               "--sensor-hz", str(self.sensor_hz)]
        for o in self.outs:
            cmd += ["--out", o]
        for o in self.control_outs:
            cmd += ["--control-out", o]
        if self.signing_key_file is not None:
            cmd += ["--signing-key", self.signing_key_file]
        cmd += ["--max-clients", str(self.max_clients), "--client-timeout", repr(self.client_timeout_s)]
        if self.stats_file is not None:
            cmd += ["--stats", self.stats_file]
        for c in self.controllers or ():
            cmd += ["--controller", c]
        if self.lockstep:
            cmd.append("--lockstep")
        if self.autopilot is not None:
            cmd += ["--autopilot", self.autopilot]
        if self.seed is not None:
            cmd += ["--seed", str(int(self.seed))]
        if self.deferred:
            cmd.append("--start=-")
        elif self.start_pose is not None:
            # one token "--start=..." so a negative X is not taken for an option
            cmd.append("--start=" + ",".join(repr(v) for v in self.start_pose))
        return cmd

    def start(self) -> "SitlProcess":
        """Launch and wait until the SITL is ready (its sockets are open)."""
        return self.launch().wait_ready()

    def launch(self) -> "SitlProcess":
        """Start the process without waiting for it."""
        env = dict(os.environ)
        root = str(Path(__file__).resolve().parents[1])
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        # stderr to a file, not a pipe: a long run must never block on a full pipe.
        self._stderr = tempfile.TemporaryFile(mode="w+")
        self.proc = subprocess.Popen(self.command(), stdout=subprocess.PIPE, stderr=self._stderr,
                                     stdin=subprocess.PIPE if self.deferred else subprocess.DEVNULL,
                                     text=True, env=env)
        return self

    def set_start(self, start) -> None:
        """The launch pose of a ``start="later"`` process: (x_m, y_m[, yaw_deg])."""
        pose = _check_start(start)
        if not self.deferred or self.proc is None or self.proc.stdin is None:
            raise RuntimeError("set_start() needs start='later' and launch()")
        self.start_pose = pose
        try:
            self.proc.stdin.write(",".join(repr(v) for v in pose) + "\n")
            self.proc.stdin.close()
        except OSError:   # the process already died: wait_ready() reports why
            pass

    def wait_ready(self) -> "SitlProcess":
        """Wait for the ready line; LinkError (with the SITL's last stderr line) if it exits or times out."""
        from .cli import READY_MARKER

        deadline = time.monotonic() + self.READY_TIMEOUT_S
        line = ""
        while time.monotonic() < deadline:
            r, _, _ = select.select([self.proc.stdout], [], [], 0.1)
            if r:
                line = self.proc.stdout.readline()
                if line.startswith(READY_MARKER):
                    return self
            if self.proc.poll() is not None:
                break
        err = ""
        if self.proc.poll() is not None:
            self._stderr.seek(0)
            lines = self._stderr.read().strip().splitlines()
            err = lines[-1] if lines else ""
        self.stop()
        raise LinkError(f"the SITL did not become ready: {err or line.strip() or 'timeout'}")

    def stop(self, timeout_s: float = 5.0) -> int | None:
        """Terminate the process; returns its exit code."""
        p = self.proc
        if p is None:
            return None
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout_s)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(timeout_s)
        for f in (p.stdout, p.stdin):
            if f is not None:
                try:
                    f.close()
                except OSError:
                    pass
        self._stderr.close()
        self.proc = None
        return p.returncode

    def __enter__(self) -> "SitlProcess":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()
