"""MAVLink transport of the SITL: the simulated vehicle (``sitl.vehicle``)
behind its MAVLink links (``sitl.link``; docs/mavlink.md).

The vehicle is system 1, component 1, MAVLink 2, common dialect. Connection
strings are pymavlink's (``udpin:127.0.0.1:14540``, ``udpout:...``,
``tcp:...``, ``tcpin:...``), or ``inproc:NAME``: the in-process transport
(``mavcore.link.pipe``), where the peer's waits run the vehicle (``service``) instead
of ``run``. Telemetry goes to every link; replies
(COMMAND_ACK, PARAM_VALUE on read, MISSION_*) go to the link the request
came from, addressed to the requester.

This module keeps the links, the pacing and lockstep (and the
HIL_ACTUATOR_CONTROLS answer that releases a frame), handing each frame's
telemetry to the links, and the dispatch: who may send a message (``sitl.auth``),
then the handler of the part that owns it. The vehicle itself (simulation,
flight stack, parameters, battery, collision prevention) is ``sitl.vehicle.Vehicle``,
stepped once per frame (``step_once``). The parts, each over the server
side of a ``mavcore.services`` protocol or the flight stack:
``sitl.command_link`` (COMMAND_LONG/INT through ``CommandServer``; what each
command does is ``sitl.commands``), ``sitl.params_link`` (PARAM_* through
``ParamServer`` and what a value changes), ``sitl.mission_link`` (MISSION_*
through ``MissionServer``, the stored lists handed to the flight stack,
MISSION_CURRENT and MISSION_ITEM_REACHED), ``sitl.setpoints`` (SET_MODE, the
offboard setpoints, OBSTACLE_DISTANCE), ``sitl.signing_link``
(SETUP_SIGNING) and the telemetry service (``mavcore.services.telemetry``: ``StreamSchedule``
says which stream is due at which vehicle time, ``TelemetryServer`` builds
the frame's messages with the encoders of ``sitl.telemetry``, whose
``DEFAULT_RATES_HZ`` are the rates below). TIMESYNC and PING are answered here.

Time and pacing
---------------
The simulation owns the clock (``Simulation.time_us``); every rate below is
in vehicle time. Free-running, frame k is released at
``t0_wall + t_k / speed`` (speed 0: as fast as possible), and incoming
messages are processed while waiting. With ``lockstep`` enabled the vehicle
clock does not start until a peer answers the first frame: its telemetry
(HIGHRES_IMU last) is re-sent four times a wall second, commands, parameters
and missions are served meanwhile, and the first HIL_ACTUATOR_CONTROLS with
``flags & 1`` and that frame's ``time_usec`` engages lockstep. So a lockstep
run does not depend on how long the peer took to connect (same seed, same
answers: the same flight). From then on each frame is

1. compute the motor command (fresh HIL_ACTUATOR_CONTROLS or the onboard
   controller on the flight stack's setpoint) and step one sensor period;
2. send the telemetry due at the new vehicle time, HIGHRES_IMU last (it
   marks the end of the frame);
3. process incoming messages until a HIL_ACTUATOR_CONTROLS with
   ``time_usec`` equal to that HIGHRES_IMU's arrives (it drives the next
   frame; all-NaN controls are a tick without override). If none arrives
   within SIM_LS_TMO seconds of wall-clock time, lockstep disengages
   (STATUSTEXT) and the loop free-runs at ``speed`` until a lockstep answer
   engages it again (from the frame being sent then).

A frame's telemetry goes out as one UDP datagram holding several whole
MAVLink packets in order (``Link.BATCH_BYTES``), so the peer is woken once
per frame; every MAVLink parser (pymavlink, MAVSDK, MAVProxy, QGC) reads
several packets from one datagram.

While the vehicle clock is stalled (lockstep wait) a HEARTBEAT still goes
out once per wall-clock second so that ground stations keep the link.

Message rates (defaults, changeable by MAV_CMD_SET_MESSAGE_INTERVAL):
HEARTBEAT 1 Hz, SYS_STATUS and BATTERY_STATUS 1 Hz (sitl/battery.py), SYSTEM_TIME 1 Hz, EXTENDED_SYS_STATE 5 Hz,
ATTITUDE / ATTITUDE_QUATERNION / LOCAL_POSITION_NED 50 Hz,
GLOBAL_POSITION_INT 10 Hz, GPS_RAW_INT 5 Hz, POSITION_TARGET_LOCAL_NED
10 Hz, HOME_POSITION 0.5 Hz, ODOMETRY off (when requested: the true state,
pose in LOCAL_NED, velocity in BODY_FRD, for tracking-error reports);
HIGHRES_IMU every sensor frame (fixed: it is the
lockstep frame marker, so its interval cannot be changed); DISTANCE_SENSOR
at each rangefinder's own rate (an interval sets all rangefinder periods,
-1 stops them being sent). An interval shorter than the sensor period means
every frame.

What the streams carry (``sitl.sensors``, ``sitl.gnss``, ``sitl.estimator``):
HIGHRES_IMU the noisy IMU and magnetometer of the frame (``sim.vector_sensors``
decides what the accelerometer fields mean); LOCAL_POSITION_NED and
GPS_RAW_INT the latest *delivered* position/velocity sample, LOCAL_POSITION_NED
stamped with its measurement time (repeated, same time_boot_ms, until the
next delivery); with ``sim.onboard_state: estimate`` (default) ATTITUDE,
ATTITUDE_QUATERNION and GLOBAL_POSITION_INT carry the onboard estimator's
attitude, bias-corrected rates and position, as PX4 reports its EKF's, and
the onboard controller and flight stack use the estimate; with ``truth``
they carry and use the true state ("true state" mode, the SITL without an
estimator). Truth kept in estimate mode, where a real stack has equivalent
information: the plant's ground contact stands for the land detector
(landed state, auto-disarm, integrator freeze), and home is the true start
point (a real stack takes its estimate at arming, within the sensors'
centimetres here). ODOMETRY is always the ground truth.

Who may control the vehicle (``sitl.auth``): control messages are accepted
only from configured controllers (by system/component ids, on a control
link, from the address they first came from), others are ignored with one
STATUSTEXT per source; read-only requests are open to anyone. ``--out``
links are telemetry-only, ``--control-out`` links carry control too. A
flood from unbound addresses is shed before parsing (``IntakeBudget``:
datagrams over 1024 bytes, and beyond 1000 per second together), so it
cannot stall the vehicle's clock; bound controllers always get through.

Signing (MAVLink 2): with ``signing_key`` every outgoing packet is signed,
control must carry a valid, fresh signature and SETUP_SIGNING is refused.
Without it, SETUP_SIGNING from a controller stores a key the same way (an
all-zero key, sent signed, turns signing off again).
"""

from __future__ import annotations

import collections
import logging
import math
import os
import select
import threading
import time
from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mavlink

from mavcore import autopilot as autopilots
from mavcore import codec
from mavcore.link.pipe import MEMORY_SCHEME
from mavcore.link.signing import SignatureVerifier, enable_outgoing_signing, signing_timestamp
from mavcore.mission.schema import Mission
from mavcore.services.command import CommandServer

from .auth import DEFAULT_CONTROLLERS, ControlPolicy, Controller, IntakeBudget
from .command_link import CommandLink
from .commands import VehicleCommands
from .flightstack import SEVERITY_INFO, SEVERITY_WARNING, StatusEvent
from .link import Link
from .mission_link import VehicleMission
from .params_link import VehicleParams
from .setpoints import VehicleSetpoints
from .signing_link import SigningSetup
from .telemetry import telemetry_service
from .vehicle import Vehicle
from .vehicle_id import COMPONENT_ID, SYSTEM_ID

_log = logging.getLogger("sitl")

_HEARTBEAT_ID = mavlink.MAVLINK_MSG_ID_HEARTBEAT


@dataclass(frozen=True)
class ServerConfig:
    """How the SITL is run.

    Attributes
    ----------
    listen : str
        Main link (pymavlink connection string); loopback by default.
    outs : tuple of str
        Extra links (e.g. ``udpout:127.0.0.1:14550`` for a ground station).
    lockstep : bool
        Allow lockstep with an actuator peer (docs/mavlink.md "Time and lockstep").
    speed : float
        Real-time factor when free-running (0: as fast as possible).
    seed : int or None
        Overrides the mission's ``sim.seed``.
    physics_hz, sensor_hz : int
    start : (x_m, y_m, yaw_deg) or None
        Launch position (ENU metres on the map; z from the DEM) and heading
        (ENU degrees, body x from east, counter-clockwise). None: the
        mission's ``sim.start_enu_m`` or the default free cell, heading east.
    spin : bool
        Busy-poll for lockstep answers (SIM_LS_SPIN). False when the peer
        shares this process (``SitlThread``): a spinning thread would only
        compete with it for the interpreter lock.
    control_outs : tuple of str
        Extra links that may carry control (``outs`` are telemetry-only);
        see ``sitl.auth``.
    controllers : tuple of sitl.auth.Controller or None
        Who may control the vehicle (None: ``sitl.auth.DEFAULT_CONTROLLERS``).
    signing_key : bytes or None
        32-byte MAVLink 2 signing key: every outgoing packet is signed,
        control must be signed, SETUP_SIGNING is refused.
    max_clients : int
        Peers a ``udpin`` link serves at most (``sitl.auth.ClientTable``).
    client_timeout_s : float
        Wall-clock seconds of silence after which a ``udpin`` peer is dropped.
    autopilot : str or None
        The flight stack the SITL speaks as (``mavcore.autopilot``: "px4",
        "ardupilot"): modes, parameters, take-off and failsafe rules. None:
        the mission's ``sim.autopilot``.
    """

    listen: str = "udpin:127.0.0.1:14540"
    outs: tuple[str, ...] = ()
    lockstep: bool = False
    speed: float = 1.0
    seed: int | None = None
    physics_hz: int = 1000
    sensor_hz: int = 250
    start: tuple[float, float, float] | None = None
    spin: bool = True
    control_outs: tuple[str, ...] = ()
    controllers: tuple[Controller, ...] | None = None
    signing_key: bytes | None = None
    max_clients: int = 8
    client_timeout_s: float = 10.0
    autopilot: str | None = None

    def __post_init__(self) -> None:
        if self.autopilot is not None:
            autopilots.get(self.autopilot)     # ValueError naming the known ones
        if self.signing_key is not None and len(self.signing_key) != 32:
            raise ValueError("signing_key must be 32 bytes")
        if not (isinstance(self.max_clients, int) and 1 <= self.max_clients <= 1024):
            raise ValueError("max_clients must be an integer in [1, 1024]")
        if not (math.isfinite(self.client_timeout_s) and 0.1 <= self.client_timeout_s <= 3600):
            raise ValueError("client_timeout_s must be in [0.1, 3600] s")
        if not (self.speed >= 0 and math.isfinite(self.speed)):
            raise ValueError("speed must be >= 0 (0: as fast as possible)")
        if self.listen.startswith(MEMORY_SCHEME) and not (self.lockstep and not self.outs
                                                           and not self.control_outs):
            raise ValueError("an in-process link (inproc:NAME) needs lockstep and no other links")
        if self.start is not None:
            st = tuple(float(v) for v in self.start)
            if len(st) == 2:
                st = st + (0.0,)
            if len(st) != 3 or not all(math.isfinite(v) for v in st):
                raise ValueError("start must be (x_m, y_m[, yaw_deg]), finite")
            object.__setattr__(self, "start", st)


class SitlServer:
    """The SITL: the simulated vehicle (``self.vehicle``) behind MAVLink links.

    Constructing it does no I/O; ``open()`` binds the links, ``run()`` loops
    until ``stop()`` (thread-safe) and ``close()`` releases the sockets.

    Parameters
    ----------
    mission : Mission
    config : ServerConfig
    """

    def __init__(self, mission: Mission, config: ServerConfig = ServerConfig()) -> None:
        self.mission = mission
        self.config = config
        self._stop = threading.Event()
        self.links: list[Link] = []
        self.lockstep_engaged = False
        #: The simulated vehicle (``sitl.vehicle``): its state and its step on the vehicle clock.
        self.vehicle = Vehicle(mission, seed=mission.sim.seed if config.seed is None else int(config.seed),
                               physics_hz=config.physics_hz, sensor_hz=config.sensor_hz, start=config.start,
                               autopilot=config.autopilot or mission.sim.autopilot, lockstep=config.lockstep)
        self._awaited_us: int | None = None
        self._released = True
        self._last_hb_wall = 0.0
        self._text_id = 0                 # STATUSTEXT id of the last text sent in chunks
        #: Link diagnostics: garbage seen, and what peers asked for that the
        #: SITL does not do (message types ignored, commands answered UNSUPPORTED).
        self.stats = {"bad_packets": 0, "ignored": collections.Counter(), "unsupported": collections.Counter(),
                      "refused": collections.Counter()}
        self._refusal_said_s = -math.inf    # wall time of the last STATUSTEXT about a refused input
        #: Who may control the vehicle (``sitl.auth``); its ``counts`` are the
        #: accepted and ignored control messages.
        self.auth = ControlPolicy(
            (config.listen, *config.control_outs),
            DEFAULT_CONTROLLERS if config.controllers is None else config.controllers,
            None if config.signing_key is None else SignatureVerifier(config.signing_key),
            key_locked=config.signing_key is not None)
        self._intake = IntakeBudget()
        self._init_parts(self.vehicle)
        self._init_dispatch()

    def _init_parts(self, v: Vehicle) -> None:
        """The protocol parts over the vehicle's pieces: what it reports and what its peers may ask."""
        state = v.state
        #: The mission, fence and rally storage and the mission progress (``sitl.mission_link``).
        self.mission_link = VehicleMission(
            self.mission.energy.max_mission_items, v.sim, v.stack, v.params, v.autopilot, v.origin,
            v.home_enu_m, lambda: state() if v.frame is not None else None, self._mav,
            self._broadcast, self._say, self._refuse)
        self.missions = self.mission_link.server     # the protocol (``mavcore.services.mission``)
        #: The PARAM_* handlers and what the values change (``sitl.params_link``).
        self.param_link = VehicleParams(v.params, v.autopilot, v.sim, v.collision_prevention,
                                        lambda: self.links, self._say, self._apply_params)
        self._apply_params()
        #: What the vehicle reports (``sitl.telemetry``: the encoders), its stream schedule and the
        #: frame's telemetry built from both (``mavcore.services.telemetry``).
        self.telemetry, self.streams, self.telemetry_server = telemetry_service(v, self._mav,
                                                                                int(time.time() * 1e6))
        #: The command protocol (``mavcore.services.command``) over the vehicle's commands (``sitl.commands``).
        self.commands = CommandServer(VehicleCommands(v.sim, v.stack, v.autopilot, v.origin, v.home_enu_m,
                                                      self.streams, self.telemetry, state, self._mav).table())
        #: COMMAND_LONG / COMMAND_INT through ``self.commands`` (``sitl.command_link``).
        self.command_link = CommandLink(self.commands, v.stack, state, self.stats["unsupported"], self._refuse)
        #: SET_MODE, the offboard setpoints and the obstacle sectors (``sitl.setpoints``).
        self.setpoints = VehicleSetpoints(v.sim, v.stack, v.collision_prevention, state, self._refuse)
        #: SETUP_SIGNING (``sitl.signing_link``).
        self.signing = SigningSetup(self.auth, lambda: self.links, self._say)

    def _init_dispatch(self) -> None:
        """The receive table: message type -> ``(link, msg)`` handler, most of them the parts'."""
        self._handlers = {
            **self.command_link.handlers(),
            "HIL_ACTUATOR_CONTROLS": self._on_actuators,
            **self.param_link.handlers(),
            **self.setpoints.handlers(),
            **self.mission_link.handlers(),
            **self.signing.handlers(),
            "TIMESYNC": self._on_timesync,
            "PING": self._on_ping,
        }

    # ------------------------------------------------------------------ params
    def _apply_params(self) -> None:
        """Push parameter values into the simulation (``VehicleParams.apply``) and the links' spin budget."""
        self.param_link.apply()
        # Spinning for the lockstep answer only pays when the peer runs on
        # another core; on one core it would only delay the peer.
        spin_us = self.vehicle.params["SIM_LS_SPIN"]
        self._spin_s = spin_us * 1e-6 if self.config.spin and (os.cpu_count() or 1) >= 2 else 0.0
        for link in self.links:
            if link.pipe is not None and not link.memory:
                link.pipe.spin.max_s = self._spin_s

    # ------------------------------------------------------------------ lifecycle
    def open(self) -> None:
        """Open every link (binds sockets). Raises OSError/ValueError on a bad address."""
        cfg = self.config
        specs = ([(cfg.listen, True, "--listen")] + [(u, False, "--out") for u in cfg.outs]
                 + [(u, True, "--control-out") for u in cfg.control_outs])
        try:
            for url, control, option in specs:
                self.links.append(Link(url, control, cfg.max_clients, cfg.client_timeout_s, option))
        except BaseException:
            self.close()
            raise
        self._apply_params()   # the links' spin budget
        for link in self.links:
            if link.memory:
                link.pipe.driver = self.service
        if cfg.signing_key is not None:
            ts = signing_timestamp(time.time())
            self.auth.verifier.timestamp = ts
            for i, link in enumerate(self.links):
                enable_outgoing_signing(link.mav, cfg.signing_key, i, ts)

    def close(self) -> None:
        for link in self.links:
            link.close()
        self.links = []

    def stop(self) -> None:
        """Ask ``run`` to return (thread-safe)."""
        self._stop.set()

    @property
    def time_us(self) -> int:
        return self.vehicle.sim.time_us

    def link_report(self) -> dict:
        """JSON-ready link statistics: who controlled the vehicle and what was
        ignored (``sitl.auth``), garbage, message types not handled, clients."""
        return {
            "control": self.auth.summary(),
            "bad_packets": self.stats["bad_packets"],
            "dropped_unparsed": {"oversized": self._intake.n_oversized, "over_rate": self._intake.n_over_rate},
            "ignored_types": dict(self.stats["ignored"]),
            "unsupported_commands": {str(k): v for k, v in self.stats["unsupported"].items()},
            "refused": dict(self.stats["refused"]),
            "links": [{"url": l.url, "control": l.control, "clients": len(l.clients),
                       "clients_evicted": l.clients.n_evicted, "clients_expired": l.clients.n_expired,
                       **({"lockstep_spins": l.pipe.spin.n_spins, "lockstep_spin_hits": l.pipe.spin.n_hits}
                          if l.pipe is not None and not l.memory else {})}
                      for l in self.links],
        }

    def run(self, max_frames: int | None = None) -> None:
        """The main loop (see the module docstring). Returns on ``stop()``."""
        if self.vehicle.frame is None:
            self._send_telemetry(self._start_clock())
            if self.config.lockstep:
                self._wait_for_first_peer()
        self._pace_reset()
        stop = self._stop
        n = 0
        while not stop.is_set():
            self.step_once()
            n += 1
            if max_frames is not None and n >= max_frames:
                break
            if self.missions.uploading:
                self.mission_link.tick()
            if self.lockstep_engaged:
                self._wait_for_answer()
            else:
                self._pace()

    def service(self) -> None:
        """One cooperative turn of ``run`` (the in-process transport,
        ``mavcore.link.pipe.MemoryPipe``): the peer's pipe calls it in the peer's
        thread whenever the peer waits for a datagram and none is queued.

        It does what ``run`` does between two waits, without waiting: the
        first call steps frame 0 and sends its telemetry; then each call
        handles the queued input up to the lockstep answer and, once that
        answer has released the frame, steps one frame and sends its
        telemetry (the peer's next datagram). So the same frames, the same
        bytes in the same order as over UDP. While the clock is held the
        wall-clock duties of ``run`` remain: frame 0 re-sent four times a
        second until lockstep engages, a HEARTBEAT once a second. A peer that
        stops asking stops the vehicle (it cannot fall silent while asking),
        so lockstep never disengages here. Needs ``lockstep``.
        """
        if self._stop.is_set():
            return
        if self.vehicle.frame is None:
            # As run() over UDP: frame 0's telemetry reaches nobody (the peer's
            # address is not known yet, so no stream's schedule advances) and
            # the peer gets the frame re-sent (``_wait_for_first_peer``).
            self._awaited_us = self._start_clock().time_us
            self._released = False
            self._coop_clock_runs = False
            self._coop_resent = time.monotonic()
            self._resend_frame()
            return
        if not self._released:
            self._poll(0.0, until_released=True)
        if not self._coop_clock_runs:     # run(): _wait_for_first_peer
            if self.lockstep_engaged and self._released:
                self._coop_clock_runs = True
                self._pace_reset()
            else:
                now = time.monotonic()
                if now - self._coop_resent >= 0.25:
                    self._coop_resent = now
                    self._resend_frame()
                return
        if self._released:
            self.step_once()
            if self.missions.uploading:
                self.mission_link.tick()
            return
        now = time.monotonic()             # run(): _wait_for_answer, the clock stalled
        if now - self._last_hb_wall >= 1.0:
            self._last_hb_wall = now
            self._broadcast(self.telemetry.heartbeat())
        if self.missions.uploading:
            self.mission_link.tick()

    # ------------------------------------------------------------------ one frame
    def step_once(self) -> None:
        """Step the vehicle one sensor frame (``Vehicle.step``), report it: the
        mission's progress, a crash, the frame's telemetry."""
        v = self.vehicle
        frame = v.step()
        self.telemetry.new_frame(frame, v.setpoint)
        if v.stack.mission is not None:
            self.mission_link.progress()
        if v.check_crash():        # announce the new system status in this frame's HEARTBEAT
            self.streams.send_now(_HEARTBEAT_ID, v.sim.time_us)
        self._flush_events()
        self._send_telemetry(frame)

    def _start_clock(self):
        """Frame 0 (``Vehicle.start``), the telemetry's current frame."""
        frame = self.telemetry.frame = self.vehicle.start()
        return frame

    def _send_telemetry(self, frame) -> None:
        """The frame's telemetry (``TelemetryServer.frame``) to every link with a peer; the
        frame then awaits its lockstep answer. No peer: nothing is built, no stream's schedule
        moves on."""
        now = frame.time_us
        self._awaited_us = now
        self._released = False
        links = self.links
        if len(links) != 1 or not links[0].has_peer:   # the usual one link with its peer: as it is
            links = [l for l in links if l.has_peer]
        if links:
            self._send_frame(links, self.telemetry_server.frame(now, frame))

    def _send_frame(self, links, items) -> None:
        """Hand a frame's ``(packer, payload)`` list to each link, one datagram per link."""
        for l in links:
            l.begin_frame()
            send, send_fast = l.send, l.send_fast
            for packer, payload in items:
                if packer is None:
                    send(payload)
                else:
                    send_fast(packer, payload)
            l.end_frame()
        ts = self.telemetry_server
        if ts.heartbeat_sent:
            ts.heartbeat_sent = False
            self._last_hb_wall = time.monotonic()

    def _mav(self):
        return self.links[0].mav if self.links else mavlink.MAVLink(None, SYSTEM_ID, COMPONENT_ID)

    # ------------------------------------------------------------------ pacing
    def _pace_reset(self) -> None:
        self._t0_wall = time.monotonic()
        self._t0_sim_us = self.vehicle.sim.time_us

    def _pace(self) -> None:
        """Free-running: process input until frame k's wall-clock release."""
        speed = self.config.speed
        self._poll(0.0)
        if speed <= 0:
            return
        deadline = self._t0_wall + (self.vehicle.sim.time_us - self._t0_sim_us) * 1e-6 / speed
        while not self._stop.is_set() and not self.lockstep_engaged:
            now = time.monotonic()
            if now >= deadline:
                if now - deadline > 0.5:   # far behind (debugger, overload): do not sprint
                    self._pace_reset()
                return
            self._poll(min(deadline - now, 0.05))

    def _wait_for_answer(self) -> None:
        """Lockstep: process input until the answer to the last HIGHRES_IMU."""
        start = time.monotonic()
        links = self.links
        if len(links) == 1 and links[0].udp and links[0].has_peer:
            # The usual frame: one read brings the answer (no heartbeat check:
            # the telemetry carried this frame's heartbeat if one was due).
            self._poll_one(links[0], 0.05, True, True)
            if self._released:
                return
        if not any(l.has_peer for l in self.links):
            self.lockstep_engaged = False
            self._pace_reset()
            return
        timeout = self.vehicle.params["SIM_LS_TMO"]
        while not self._released and not self._stop.is_set():
            now = time.monotonic()
            if now - start > timeout:
                self.lockstep_engaged = False
                self._say(SEVERITY_WARNING, f"Lockstep peer silent for {timeout:g} s: free-running")
                self._pace_reset()
                return
            if now - self._last_hb_wall >= 1.0:
                self._last_hb_wall = now
                self._broadcast(self.telemetry.heartbeat())
            self._poll(min(0.05, timeout - (now - start) + 1e-3), until_released=True)

    def _wait_for_first_peer(self) -> None:
        """Lockstep: hold the vehicle clock at the first frame until a peer
        answers it, re-sending that frame's telemetry four times a wall
        second so a peer that connects late finds it (and so the run does
        not depend on how long the peer took to start)."""
        last = 0.0
        n_peers = 0
        while not self._stop.is_set() and not (self.lockstep_engaged and self._released):
            now = time.monotonic()
            peers = sum(len(l.clients) for l in self.links)
            if now - last >= 0.25 or peers > n_peers:   # at once for a new peer
                last = now
                n_peers = peers
                self._resend_frame()
            self._poll(0.05, until_released=True)

    def _resend_frame(self) -> None:
        """Send every enabled stream of the current frame once, HIGHRES_IMU last."""
        links = [l for l in self.links if l.has_peer]
        if not links or self.vehicle.frame is None:
            return
        self._send_frame(links, self.telemetry_server.whole_frame())
        self._last_hb_wall = time.monotonic()

    def _poll(self, timeout_s: float, until_released: bool = False) -> None:
        """Read and handle everything available; wait up to ``timeout_s`` for the first."""
        links = self.links
        if timeout_s > 0 and len(links) == 1 and links[0].udp:
            self._poll_one(links[0], timeout_s, until_released)
            return
        if timeout_s > 0:
            try:
                ready, _, _ = select.select([l.fd for l in links], [], [], timeout_s)
            except (OSError, ValueError):
                return
            if not ready:
                return
        for link in links:
            for _ in range(1000):
                try:
                    if link.udp:
                        data = link.recv_datagram()
                        if data is None:
                            if link.gone:
                                self._forget_gone(link)
                            break
                        ans, msgs = self._decode_datagram(link, data)
                    else:
                        ans = None
                        msgs = link.receive()
                        if msgs is None:
                            break
                except Exception:   # garbage must never stop the vehicle
                    self.stats["bad_packets"] += 1
                    break
                if self._dispatch(link, ans, msgs, until_released):
                    return

    def _poll_one(self, link: Link, timeout_s: float, until_released: bool, spin: bool = False) -> None:
        """``_poll`` for a single datagram link: the first read blocks in the
        kernel (SO_RCVTIMEO) instead of in select(), after the adaptive spin
        (``spin``, ``mavcore.link.pipe.AdaptiveSpin``); later reads do not wait."""
        # A steady timeout value avoids a setsockopt() per frame.
        wait = 0.05 if timeout_s >= 0.05 else timeout_s
        for k in range(1000):
            try:
                data = link.recv_datagram(wait if k == 0 else 0.0, spin and k == 0)
                if data is None:
                    if link.gone:
                        self._forget_gone(link)
                    return
                ans, msgs = self._decode_datagram(link, data)
            except Exception:   # garbage must never stop the vehicle
                self.stats["bad_packets"] += 1
                return
            if self._dispatch(link, ans, msgs, until_released):
                return

    def _decode_datagram(self, link: Link, data: bytes):
        """(lockstep answer or None, messages) of one UDP datagram: the answer
        (one packet per frame) is decoded without pymavlink's parser when it
        is alone in its datagram (and dropped unless its sender may control)."""
        if link.server and link.last_addr not in link.clients.pinned and \
                not self._intake.admit(len(data), time.monotonic()):
            return None, ()      # an unbound source over its budget: dropped unparsed (sitl.auth.IntakeBudget)
        ans = codec.decode_actuator_datagram(data)
        if ans is None:
            return None, link.parse(data)
        v = self.auth.authorize(link.url, link.last_addr, "HIL_ACTUATOR_CONTROLS", None, data[5], data[6],
                                data, time.monotonic(), self.vehicle.sim.time_us * 1e-6)
        if (v.bindings_changed or v.report or not v.accepted) and not self._verdict(v):
            return None, ()
        return ans, ()

    def _dispatch(self, link: Link, ans, msgs, until_released: bool) -> bool:
        """Act on a decoded datagram; True when the caller should stop reading
        (``until_released`` and the lockstep answer has released the frame)."""
        if ans is not None:
            self._on_answer(ans)
        for msg in msgs:
            self._handle(link, msg)
        return until_released and self._released

    # ------------------------------------------------------------------ dispatch
    def _handle(self, link: Link, msg) -> None:
        mtype = msg.get_type()
        if mtype == "BAD_DATA":
            self.stats["bad_packets"] += 1
            return
        sysid, compid = msg.get_srcSystem(), msg.get_srcComponent()
        now, vehicle_s = time.monotonic(), self.vehicle.sim.time_us * 1e-6
        self.auth.observe(link.url, link.last_addr, sysid, compid, now, vehicle_s)
        handler = self._handlers.get(mtype)
        if handler is None:
            self.stats["ignored"][mtype] += 1
            return
        if sysid == SYSTEM_ID and compid == COMPONENT_ID:
            return   # our own echo
        command = msg.command if mtype in ("COMMAND_LONG", "COMMAND_INT") else None
        v = self.auth.authorize(link.url, link.last_addr, mtype, command, sysid, compid, msg.get_msgbuf(), now,
                                vehicle_s)
        if v.bindings_changed or v.report or not v.accepted:
            if not self._verdict(v):
                return
        try:
            handler(link, msg)
        except Exception:   # never let one malformed message stop the vehicle
            self.stats["bad_packets"] += 1
        self._flush_events()

    def _forget_gone(self, link: Link) -> None:
        """Peers whose socket closed (ICMP port unreachable): no more telemetry
        to them, and a controller bound there is free for its next address at
        once (a restarted companion re-attaches without waiting for the
        binding's silence timeout)."""
        gone, link.gone = link.gone, []
        for addr in gone:
            link.clients.forget(addr)
            for sysid, compid in self.auth.release(link.url, addr):
                self._say(SEVERITY_INFO, f"controller {sysid}/{compid} at {addr[0]}:{addr[1]} gone (port closed)")
        link.clients.pinned = self.auth.bound_addresses(link.url)

    def _verdict(self, v) -> bool:
        """Act on a ``sitl.auth.Verdict`` (pins, STATUSTEXT); returns ``v.accepted``."""
        if v.bindings_changed:
            for link in self.links:
                if link.server:
                    link.clients.pinned = self.auth.bound_addresses(link.url)
        if v.report:
            self._say(SEVERITY_WARNING if not v.accepted else SEVERITY_INFO, v.report)
        return v.accepted

    def _broadcast(self, msg) -> None:
        for l in self.links:
            if l.has_peer:
                l.send(msg)

    def _say(self, severity: int, text: str) -> None:
        self.vehicle.stack.events.append(StatusEvent(severity, text))
        self._flush_events()

    def _flush_events(self) -> None:
        if self.vehicle.stack.events:
            for ev in self.vehicle.stack.pop_events():
                _log.info("t=%.3f s: %s", self.vehicle.sim.time_us * 1e-6, ev.text)
                if len(ev.text) <= codec.STATUSTEXT_CHUNK:
                    self._broadcast(codec.statustext(self._mav(), ev.severity, ev.text))
                else:
                    self._text_id = self._text_id % 65535 + 1
                    for m in codec.statustext_chunks(self._mav(), ev.severity, ev.text, self._text_id):
                        self._broadcast(m)

    #: Wall seconds between two STATUSTEXTs about refused inputs (a flood of
    #: bad messages must not become a flood of texts to every link).
    REFUSAL_TEXT_S = 1.0

    def _refuse(self, kind: str, why: str) -> None:
        """Count a message refused by ``mavcore.link.command_rules`` and say why
        (at most once per ``REFUSAL_TEXT_S``)."""
        self.stats["refused"][kind] += 1
        now = time.monotonic()
        if now - self._refusal_said_s >= self.REFUSAL_TEXT_S:
            self._refusal_said_s = now
            self._say(SEVERITY_WARNING, f"Refused {kind}: {why}")

    # ------------------------------------------------------------------ lockstep answer
    def _on_actuators(self, link, msg) -> None:
        self._on_answer(codec.decode_actuator_controls(msg))

    def _on_answer(self, ans: codec.ActuatorAnswer) -> None:
        now = self.vehicle.sim.time_us
        if ans.refused is not None:       # unusable controls: still a lockstep answer
            self._refuse("HIL_ACTUATOR_CONTROLS", ans.refused)
        self.vehicle.stack.actuator_controls(now, ans.motor_cmd)
        if not (ans.lockstep and self.config.lockstep):
            return
        if not self.lockstep_engaged:
            self.lockstep_engaged = True
            self._say(SEVERITY_INFO, "Lockstep engaged")
        if ans.time_usec == self._awaited_us:
            self._released = True

    # ------------------------------------------------------------------ misc
    def _on_timesync(self, link, msg) -> None:
        if int(msg.tc1) != 0:
            return   # an answer to someone else's request
        link.reply(link.mav.timesync_encode(self.vehicle.sim.time_us * 1000, int(msg.ts1)))

    def _on_ping(self, link, msg) -> None:
        if int(msg.target_system) != 0 or int(msg.target_component) != 0:
            return   # a response, not a request
        link.reply(link.mav.ping_encode(int(msg.time_usec), int(msg.seq), msg.get_srcSystem(),
                                        msg.get_srcComponent()))

