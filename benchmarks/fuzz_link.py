"""Fuzz and attack the MAVLink links: the SITL during a companion flight, and
the companion's receive path. All traffic on 127.0.0.0/8.

Usage::

    python benchmarks/fuzz_link.py [--datagrams 100000] [--signing on|off|both] [--cut 60]
        [--rate 2000] [--seed 7] [--json out.json]

Flight campaign (``run_flight_campaign``): the bundled SITL runs in a thread
of this process (lockstep, optionally with a signing key); the companion
flies the flat-rectangle mission with the geometric controller (``companion
fly``'s ``execute``; with the same key); meanwhile

- a fuzzer sends ``--datagrams`` hostile datagrams (``Fuzzer``: valid MAVLink 2
  of every message type with random fields and ids, bad CRCs, truncated,
  oversized, MAVLink 1, bit-flipped, random bytes, bad signature blocks,
  control from foreign system ids, control with the companion's ids from
  other ports, HIGHRES_IMU/ODOMETRY with future or past timestamps) to the
  SITL's port from a pool of source ports, at ``--rate`` per second;
- a racer listens to the SITL's telemetry and answers every HIGHRES_IMU at
  once with a spoofed lockstep HIL_ACTUATOR_CONTROLS of zeros under the
  companion's ids (1/191), trying to win the race for each frame.

Figures: datagrams sent by kind, crashes (the SITL thread failing, the
companion raising), control messages the SITL accepted from any address
other than the companion's (every call of its policy is recorded), the
flight's outcome and tracking error.

Connection campaign (``run_connection_campaign``): a companion ``Connection``
on ``udpin`` receives a vehicle's stream (heartbeat, then HIGHRES_IMU frames)
interleaved with the fuzzer's datagrams from other ports, including spoofed
vehicle messages (1/1) with far timestamps. Figures: datagrams, crashes,
foreign messages accepted, vehicle frames lost.

The test suite runs both with small numbers (tests/test_fuzz.py).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import socket
import struct
import sys
import threading
import time
from collections import Counter
from pathlib import Path

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

KINDS = ("random_fields", "bad_crc", "truncated", "oversized", "mavlink1", "bitflip", "random_bytes",
         "bad_signature", "foreign_control", "spoofed_ids_control", "timestamp_jump", "long_header")

_ALL_CLASSES = sorted(mavlink.mavlink_map.values(), key=lambda c: c.id)
_V1_CLASSES = [c for c in _ALL_CLASSES if c.id < 256]


def _field_specs(cls) -> list[tuple[str, int]]:
    """(type, array length or 0) of each constructor argument of a pymavlink message class."""
    specs = _SPECS.get(cls)
    if specs is None:
        lengths = dict(zip(cls.ordered_fieldnames, cls.array_lengths))
        specs = _SPECS[cls] = [(t, int(lengths[n])) for n, t in zip(cls.fieldnames, cls.fieldtypes)]
    return specs


_SPECS: dict = {}


_SPECIAL_FLOATS = (math.nan, math.inf, -math.inf, 3.4e38, -3.4e38, 0.0)
_INT_BITS = {"char": 8, "uint8_t": 8, "int8_t": 8, "uint16_t": 16, "int16_t": 16, "uint32_t": 32,
             "int32_t": 32, "uint64_t": 64, "int64_t": 64}


def _values(rng, ftype: str, n: int) -> list:
    """``n`` random values of a MAVLink field type: mostly ordinary, 5-20 % at the edges."""
    if ftype in ("float", "double"):
        v = (rng.normal(0.0, 1.0, n) * 10.0 ** rng.integers(0, 6, n)).astype(np.float32).astype(float).tolist()
        for i in np.nonzero(rng.random(n) < 0.05)[0]:
            v[i] = _SPECIAL_FLOATS[int(rng.integers(0, len(_SPECIAL_FLOATS)))]
        return v
    bits = _INT_BITS[ftype]
    signed = ftype.startswith("int")
    lo, hi = (-(1 << (bits - 1)), (1 << (bits - 1)) - 1) if signed else (0, (1 << bits) - 1)
    v = [int(x) for x in rng.integers(0, 1 << min(bits, 63), n, dtype=np.uint64)]
    if signed:
        v = [x - (1 << (bits - 1)) if bits < 64 else x for x in v]
    edges = (lo, hi, 0, 1)
    for i in np.nonzero(rng.random(n) < 0.2)[0]:
        v[i] = edges[int(rng.integers(0, 4))]
    return v


def random_message(rng, cls):
    """An instance of ``cls`` with random field values of the right types."""
    args = []
    for ftype, n in _field_specs(cls):
        if ftype == "char":
            args.append(rng.bytes(n or 1))
        elif n:
            args.append(_values(rng, ftype, n))
        else:
            args.append(_values(rng, ftype, 1)[0])
    return cls(*args)


class Fuzzer:
    """Seeded hostile datagrams (pure: a ``numpy.random.Generator`` in, bytes out).

    Parameters
    ----------
    rng : numpy.random.Generator
    victim_ids : (sysid, compid)
        Ids to impersonate in ``spoofed_ids_control`` (the companion's 1/191
        against the SITL, the vehicle's 1/1 against the companion).
    kinds : sequence of str
        Which of ``KINDS`` to draw from (uniformly).
    """

    def __init__(self, rng: np.random.Generator, victim_ids=(1, 191), kinds=KINDS) -> None:
        self.rng = rng
        self.victim_ids = tuple(victim_ids)
        self.kinds = tuple(kinds)
        self._mav = {}

    def mav(self, sysid: int, compid: int, signed_garbage: bool = False):
        key = (sysid, compid, signed_garbage)
        m = self._mav.get(key)
        if m is None:
            m = mavlink.MAVLink(None, srcSystem=sysid, srcComponent=compid)
            if signed_garbage:   # signed with a key nobody else has
                m.signing.secret_key = bytes(self.rng.integers(0, 256, 32, dtype=np.uint8))
                m.signing.sign_outgoing = True
                m.signing.timestamp = int(self.rng.integers(0, 1 << 47))
            self._mav[key] = m
        m.seq = int(self.rng.integers(0, 256))
        return m

    def _ids(self):
        r = self.rng.random()
        if r < 0.6:
            return int(self.rng.integers(2, 256)), int(self.rng.integers(0, 256))   # foreign
        if r < 0.8:
            return self.victim_ids
        return (1, 255, 245)[int(self.rng.integers(0, 3))], (1, 190, 191, 230)[int(self.rng.integers(0, 4))]

    def _packet(self, sysid=None, compid=None, cls=None, v1=False, signed=False) -> bytes:
        rng = self.rng
        if sysid is None:
            sysid, compid = self._ids()
        for _ in range(20):
            c = cls or (_V1_CLASSES if v1 else _ALL_CLASSES)[int(rng.integers(0, len(_V1_CLASSES if v1 else
                                                                                     _ALL_CLASSES)))]
            try:
                return bytes(random_message(rng, c).pack(self.mav(sysid, compid, signed), force_mavlink1=v1))
            except Exception:   # a field value pymavlink cannot pack: draw again
                continue
        return bytes(rng.integers(0, 256, 20, dtype=np.uint8))

    def _control(self, sysid: int, compid: int) -> bytes:
        rng = self.rng
        cls = [mavlink.MAVLink_command_long_message, mavlink.MAVLink_command_int_message,
               mavlink.MAVLink_set_mode_message, mavlink.MAVLink_set_position_target_local_ned_message,
               mavlink.MAVLink_hil_actuator_controls_message, mavlink.MAVLink_param_set_message,
               mavlink.MAVLink_mission_count_message, mavlink.MAVLink_mission_item_int_message,
               mavlink.MAVLink_mission_clear_all_message, mavlink.MAVLink_mission_set_current_message,
               mavlink.MAVLink_setup_signing_message][int(rng.integers(0, 11))]
        m = random_message(rng, cls)
        if hasattr(m, "target_system"):
            m.target_system, m.target_component = 1, int(rng.integers(0, 2))
        if cls is mavlink.MAVLink_command_long_message or cls is mavlink.MAVLink_command_int_message:
            m.command = (400, 22, 21, 20, 176, 511, 300, 31010)[int(rng.integers(0, 8))]
            if m.command == 400:
                m.param1, m.param2 = 0.0, 21196.0          # force disarm
        try:
            return bytes(m.pack(self.mav(sysid, compid)))
        except Exception:
            return self._packet(sysid, compid)

    def datagram(self) -> tuple[str, bytes]:
        """One hostile datagram: (kind, bytes)."""
        kind = self.kinds[int(self.rng.integers(0, len(self.kinds)))]
        try:
            return kind, self._make(kind)
        except Exception:   # a value pymavlink cannot pack: random bytes of the same kind's size
            return kind, bytes(self.rng.integers(0, 256, int(self.rng.integers(1, 300)), dtype=np.uint8))

    def _make(self, kind: str) -> bytes:
        rng = self.rng
        if kind == "random_fields":
            data = self._packet()
        elif kind == "bad_crc":
            b = bytearray(self._packet())
            b[-1 if b[2] == 0 else -14] ^= int(rng.integers(1, 256))
            data = bytes(b)
        elif kind == "truncated":
            p = self._packet()
            data = p[:int(rng.integers(1, max(2, len(p))))]
        elif kind == "oversized":
            if rng.random() < 0.5:
                data = bytes(rng.integers(0, 256, int(rng.integers(1500, 65000)), dtype=np.uint8))
            else:   # many whole packets in one datagram (a few, repeated)
                parts = [self._packet() for _ in range(3)]
                data = b"".join(parts[int(i)] for i in rng.integers(0, 3, int(rng.integers(20, 200))))[:65000]
        elif kind == "mavlink1":
            data = self._packet(v1=True)
        elif kind == "bitflip":
            b = bytearray(self._control(*self.victim_ids))
            for _ in range(int(rng.integers(1, 4))):
                b[int(rng.integers(0, len(b)))] ^= 1 << int(rng.integers(0, 8))
            data = bytes(b)
        elif kind == "random_bytes":
            data = bytes(rng.integers(0, 256, int(rng.integers(1, 400)), dtype=np.uint8))
        elif kind == "bad_signature":
            sysid, compid = self._ids()
            data = self._packet(sysid, compid, signed=True)
        elif kind == "foreign_control":
            data = self._control(int(rng.integers(2, 256)), int(rng.integers(0, 256)))
        elif kind == "spoofed_ids_control":
            data = self._control(*self.victim_ids)
        elif kind == "timestamp_jump":
            sysid, compid = (1, 1) if rng.random() < 0.7 else self._ids()
            t = (int(rng.integers(10**8, 10**12)), 0, (1 << 64) - 1)[int(rng.integers(0, 3))]
            mav = self.mav(sysid, compid)
            which = rng.integers(0, 3)
            if which == 0:
                m = mav.highres_imu_encode(t, *([float(rng.normal())] * 13), 0, 0)
            elif which == 1:
                m = mav.local_position_ned_encode(t & 0xFFFFFFFF, 0, 0, -50.0, 0, 0, 0)
            else:
                m = mav.hil_actuator_controls_encode(t, [0.0] * 16, 0, 1)
            data = bytes(m.pack(mav))
        else:   # long_header: a v2 header promising 255 bytes, then little
            data = bytes([0xFD, 255, 0, 0, 0, 1, 1, 105, 0, 0]) + bytes(rng.integers(0, 256, 8, dtype=np.uint8))
        return data


def inet_sockets(pid: int) -> list[tuple[str, tuple, tuple]]:
    """Every IPv4/IPv6 UDP and TCP socket process ``pid`` holds, from /proc:
    (proto, local (ip, port), remote (ip, port)); IPv6 entries as raw hex."""
    inodes = set()
    for fd in Path(f"/proc/{pid}/fd").iterdir():
        try:
            m = re.fullmatch(r"socket:\[(\d+)\]", os.readlink(fd))
        except OSError:
            continue
        if m:
            inodes.add(int(m.group(1)))
    out = []
    for proto in ("udp", "tcp", "udp6", "tcp6"):
        for line in Path(f"/proc/{pid}/net/{proto}").read_text().splitlines()[1:]:
            f = line.split()
            if int(f[9]) not in inodes:
                continue
            if proto.endswith("6"):
                out.append((proto, (f[1],), (f[2],)))
            else:
                out.append((proto, _hexaddr(f[1]), _hexaddr(f[2])))
    return out


def _hexaddr(hexpair: str) -> tuple[str, int]:
    ip, port = hexpair.split(":")
    return socket.inet_ntoa(struct.pack("<I", int(ip, 16))), int(port, 16)


class _Sender(threading.Thread):
    """Sends the fuzzer's datagrams to ``dest`` from a pool of source ports.

    ``pregenerate``: draw every datagram before the attack starts, so that
    making them (about a millisecond each) does not compete with the flight
    for this process's interpreter lock (the test suite's small runs)."""

    def __init__(self, fuzzer: Fuzzer, dest, n: int, rate: float, n_ports: int = 16,
                 pregenerate: bool = False) -> None:
        super().__init__(daemon=True, name="fuzzer")
        self.fuzzer, self.dest, self.n, self.rate = fuzzer, dest, n, rate
        self.ready = [fuzzer.datagram() for _ in range(n)] if pregenerate else None
        self.socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n_ports)]
        for s in self.socks:
            s.bind(("127.0.0.1", 0))
        self.sent: Counter = Counter()
        self.stop = threading.Event()
        self.go = threading.Event()     # set when the attack may start
        self.error: BaseException | None = None

    def run(self) -> None:
        try:
            self.go.wait(120.0)
            t0 = time.monotonic()
            rng = self.fuzzer.rng
            for i in range(self.n):
                if self.stop.is_set():
                    break
                kind, data = self.ready[i] if self.ready is not None else self.fuzzer.datagram()
                s = self.socks[int(rng.integers(0, len(self.socks)))]
                try:
                    s.sendto(data, self.dest)
                except OSError:   # EMSGSIZE / buffer full: counted as not sent
                    self.sent["send_error"] += 1
                    continue
                self.sent[kind] += 1
                if self.rate > 0:
                    ahead = t0 + (i + 1) / self.rate - time.monotonic()
                    if ahead > 0:
                        time.sleep(ahead)
        except BaseException as exc:   # reported, never silent
            self.error = exc
        finally:
            for s in self.socks:
                s.close()


def imu_time_usec(datagram: bytes) -> int | None:
    """``time_usec`` of the last HIGHRES_IMU among the MAVLink 2 packets of a
    datagram, read from the bytes (no parser: the racer must be quick)."""
    i, n, t = 0, len(datagram), None
    while i + 12 <= n and datagram[i] == 0xFD:
        end = i + 12 + datagram[i + 1] + (13 if datagram[i + 2] & 1 else 0)
        if datagram[i + 7] == 105 and datagram[i + 8] == 0 and datagram[i + 9] == 0:
            payload = datagram[i + 10:i + 10 + min(8, datagram[i + 1])]
            t = int.from_bytes(payload + bytes(8 - len(payload)), "little")
        i = end
    return t


class _Racer(threading.Thread):
    """Listens to the SITL's telemetry (as a foreign ground station) and answers
    each HIGHRES_IMU at once with a spoofed lockstep HIL_ACTUATOR_CONTROLS of
    zeros under the companion's ids."""

    def __init__(self, dest) -> None:
        super().__init__(daemon=True, name="racer")
        self.dest = dest
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.2)
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=191)
        self.stop = threading.Event()
        self.start_after: threading.Event | None = None
        self.answers = 0

    def run(self) -> None:
        if self.start_after is not None:
            self.start_after.wait(120.0)
        gcs = mavlink.MAVLink(None, 42, 1)
        hb = bytes(gcs.heartbeat_encode(6, 8, 0, 0, 4).pack(gcs))
        last_hb = 0.0
        while not self.stop.is_set():
            now = time.monotonic()
            if now - last_hb > 0.5:     # stay a telemetry client (the table evicts the silent)
                self.sock.sendto(hb, self.dest)
                last_hb = now
            try:
                data = self.sock.recv(65536)
            except OSError:
                continue
            t = imu_time_usec(data)
            if t is not None:
                ans = self.mav.hil_actuator_controls_encode(t, [0.0] * 16, 0, 1)
                self.sock.sendto(bytes(ans.pack(self.mav)), self.dest)
                self.answers += 1
        self.sock.close()


def _small_plan(mission, path: Path) -> Path:
    """A short plan.json along one corridor of flat-rectangle (no planning cost)."""
    xs = [3.0 + 3.0 * i for i in range(7)]
    z = mission.flight.height_agl_m
    wps = [{"t": 3.0 * i, "p": [x, 8.75, z], "v": [0.0] * 3, "a": [0.0] * 3, "corner": i in (0, 6)}
           for i, x in enumerate(xs)]
    from companion.plan_io import STATS_KEYS, TIMING_KEYS
    h = mission.home
    doc = {"frame": "ENU", "origin": {"lat": h.lat, "lon": h.lon, "alt_m": h.alt_m},
           "path": [[xs[0], 8.75], [xs[-1], 8.75]], "waypoints": wps,
           "trajectory": {"t": [0.0, 18.0], "p": [wps[0]["p"], wps[-1]["p"]], "v": [[0.0] * 3] * 2,
                          "a": [[0.0] * 3] * 2, "pointing": [[0.0, 1.0, 0.0]] * 2},
           "target_enu_m": [12.0, 20.0, 1.5],
           "stats": {k: 0.0 for k in STATS_KEYS}, "timings_s": {k: 0.0 for k in TIMING_KEYS}}
    path.write_text(json.dumps(doc))
    return path


def run_flight_campaign(n_datagrams: int, signing: bool, cut_s: float | None, rate: float, seed: int,
                        workdir: Path, racer: bool = True, settle_s: float = 5.0, pregenerate: bool = False) -> dict:
    """Fly the companion against the SITL while fuzzing the SITL (module docstring).

    The SITL is a ``python -m sitl`` subprocess (lockstep, ``--stats``: the
    control it accepted, by source, is read back at its exit). The attackers
    start once the companion controls the vehicle (the vehicle acknowledged
    its first control command): without signing, the ids of a controller belong to whoever
    uses them first (``sitl.auth``), so this is an attack during a flight.

    Returns
    -------
    dict of figures (see ``main``).
    """
    from companion.commands.fly import execute, open_link, prepare
    from mavcore.mission import load_mission
    from sitl.api import SitlProcess

    mission_path = ROOT / "missions" / "flat-rectangle" / "mission.yaml"
    mission = load_mission(mission_path)
    key_file = None
    key = None
    if signing:
        key_file = workdir / "fuzz.key"
        key_file.write_bytes(bytes(np.random.default_rng(seed + 1).integers(0, 256, 32, dtype=np.uint8)))
        key = key_file.read_bytes()
    stats_file = workdir / "sitl-stats.json"
    fp = prepare(mission, str(_small_plan(mission, workdir / "plan.json")))
    figures: dict = {"signing": signing, "datagrams": 0, "crashes": 0}
    # The companion is the only controller of this vehicle (``--controller 1/191``): without
    # signing, a configured controller nobody uses (the default ground stations) could be
    # claimed by anyone on the link (sitl.auth), which no rule can tell from a real one.
    sitl = SitlProcess(mission_path, lockstep=True, speed=1.0, signing_key_file=key_file, stats_file=stats_file,
                       controllers=("1/191",))
    sitl.start()
    host, port = sitl.listen.split(":")[1:]
    dest = (host, int(port))
    sender = _Sender(Fuzzer(np.random.default_rng(seed)), dest, n_datagrams, rate, pregenerate=pregenerate)
    rac = _Racer(dest) if racer else None
    result = None
    conn = None
    try:
        conn = open_link(sitl.url, str(workdir / "flight.tlog"), key)
        companion = "%s:%d" % conn._pipe.sock.getsockname()
        poll = conn.poll
        from sitl.auth import is_control

        def first_control_ack_starts_the_attack(*a, **k):
            msgs = poll(*a, **k)
            if not sender.go.is_set():
                for m in msgs:
                    if m.get_type() == "COMMAND_ACK" and m.result == 0 and is_control("COMMAND_LONG", m.command):
                        sender.go.set()      # the vehicle obeyed the companion: it is bound
            return msgs
        conn.poll = first_control_ack_starts_the_attack
        sender.start()
        if rac is not None:
            rac.start_after = sender.go
            rac.start()
        try:
            result = execute(mission, fp, sitl.url, "companion", str(workdir / "flight.tlog"), None, cut_s,
                             {"mute_streams": (), "settle_s": settle_s}, conn=conn)
        except Exception as exc:   # the companion must not raise: a crash
            figures["crashes"] += 1
            figures["companion_error"] = f"{type(exc).__name__}: {exc}"
    finally:
        sender.go.set()
        sender.stop.set()
        sender.join(10.0)
        if rac is not None:
            rac.stop.set()
            rac.join(2.0)
        rc = sitl.stop()
    if rc not in (0, None):
        figures["crashes"] += 1
        figures["sitl_exit_code"] = rc
    if sender.error is not None:
        figures["fuzzer_error"] = repr(sender.error)
    figures["datagrams"] = sum(v for k, v in sender.sent.items() if k != "send_error")
    figures["by_kind"] = dict(sender.sent)
    figures["racer_answers"] = 0 if rac is None else rac.answers
    try:
        st = json.loads(stats_file.read_text())
    except (OSError, ValueError):
        figures["crashes"] += 1        # the SITL did not exit cleanly: no statistics
        st = None
    if st is not None:
        ctl = st["control"]
        foreign = [a for a in ctl["accepted_from"] if a["address"] != companion]
        figures["accepted_control_from_companion"] = sum(a["messages"] for a in ctl["accepted_from"]
                                                         if a["address"] == companion)
        figures["accepted_foreign_control"] = sum(a["messages"] for a in foreign)
        figures["sitl_ignored_control"] = ctl["ignored"]
        figures["sitl_rebound"] = ctl["rebound"]
        figures["sitl_bad_packets"] = st["bad_packets"]
        figures["sitl_dropped_unparsed"] = st["dropped_unparsed"]
        figures["sitl_clients_evicted"] = sum(l["clients_evicted"] for l in st["links"])
    if conn is not None:
        figures["companion_link"] = conn.link_stats().to_dict()
    if result is not None:
        rep = result.report
        figures["completed"] = bool(rep.completed)
        figures["error"] = rep.error
        figures["max_error_m"] = rep.tracking.max_error_m
        figures["rms_error_m"] = rep.tracking.rms_error_m
        figures["n_tracking_samples"] = rep.tracking.n_samples
        figures["sim_time_s"] = rep.sim_time_s
        figures["report_link"] = rep.link
    return figures


def run_connection_campaign(n_datagrams: int, n_frames: int, seed: int) -> dict:
    """Fuzz a companion ``Connection`` (udpin) while a vehicle streams frames to it.

    The vehicle (its own port) sends a heartbeat, then ``n_frames`` HIGHRES_IMU
    at 4 ms steps of vehicle time, interleaved with the fuzzer's datagrams from
    other ports (a third of them spoofing 1/1 with far timestamps).
    """
    from companion.link import Connection
    from sitl.api import free_udp_port

    rng = np.random.default_rng(seed)
    port = free_udp_port()
    conn = Connection(f"udpin:127.0.0.1:{port}").open()
    dest = ("127.0.0.1", port)
    veh = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    veh.bind(("127.0.0.1", 0))
    vmav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    fuzz = Fuzzer(rng, victim_ids=(1, 1))
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(8)]
    sent: Counter = Counter()
    got = []
    crashes = 0
    t_us = 10_000_000
    expected = []
    try:
        veh.sendto(bytes(vmav.heartbeat_encode(2, 12, 0, 0, 3).pack(vmav)), dest)
        per_frame = max(1, n_datagrams // max(1, n_frames))
        k = 0
        while k < n_frames or sum(sent.values()) < n_datagrams:
            for _ in range(per_frame):
                if sum(sent.values()) >= n_datagrams:
                    break
                kind, data = fuzz.datagram()
                try:
                    socks[int(rng.integers(0, len(socks)))].sendto(data, dest)
                    sent[kind] += 1
                except OSError:
                    sent["send_error"] += 1
            if k < n_frames:
                t = t_us + 4000 * k
                veh.sendto(bytes(vmav.highres_imu_encode(t, *([0.5] * 13), 0, 0).pack(vmav)), dest)
                expected.append(t)
                k += 1
            try:
                got += [m for m in conn.poll(0.0) if m.get_type() == "HIGHRES_IMU"]
            except Exception:
                crashes += 1
        end = time.monotonic() + 2.0
        while time.monotonic() < end and len(got) < len(expected):
            try:
                got += [m for m in conn.poll(0.05) if m.get_type() == "HIGHRES_IMU"]
            except Exception:
                crashes += 1
    finally:
        stats = conn.link_stats().to_dict()
        conn.close()
        veh.close()
        for s in socks:
            s.close()
    times = [int(m.time_usec) for m in got]
    return {"datagrams": sum(v for k, v in sent.items() if k != "send_error"), "by_kind": dict(sent),
            "crashes": crashes, "vehicle_frames_sent": len(expected),
            "vehicle_frames_received": len(set(times) & set(expected)),
            "foreign_frames_accepted": len([t for t in times if t not in set(expected)]),
            "link": stats}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--datagrams", type=int, default=100_000, help="per flight campaign (default %(default)s)")
    ap.add_argument("--signing", choices=("on", "off", "both"), default="both")
    ap.add_argument("--cut", type=float, default=None, help="flight cut (s); default: the whole plan (18 s)")
    ap.add_argument("--rate", type=float, default=2000.0, help="fuzz datagrams per wall second")
    ap.add_argument("--connection-datagrams", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json", default=None, help="write the figures here")
    args = ap.parse_args(argv)
    import tempfile

    out = {}
    modes = {"on": [True], "off": [False], "both": [False, True]}[args.signing]
    for signing in modes:
        with tempfile.TemporaryDirectory() as d:
            f = run_flight_campaign(args.datagrams, signing, args.cut, args.rate, args.seed, Path(d))
            # the flight must last until every datagram went out: fly it again if needed
            flights = 1
            total = f
            while total["datagrams"] < args.datagrams and total["crashes"] == 0 and flights < 20:
                g = run_flight_campaign(args.datagrams - total["datagrams"], signing, args.cut, args.rate,
                                        args.seed + flights, Path(d))
                flights += 1
                total = _merge(total, g)
            total["flights"] = flights
        out[f"flight_signing_{'on' if signing else 'off'}"] = total
        print(json.dumps({k: v for k, v in total.items() if k not in ("by_kind",)}, default=str))
    c = run_connection_campaign(args.connection_datagrams, max(1000, args.connection_datagrams // 20), args.seed)
    out["companion_connection"] = c
    print(json.dumps({k: v for k, v in c.items() if k != "by_kind"}))
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=2, default=str) + "\n")
    bad = any(v.get("crashes") for v in out.values()) or any(
        v.get("accepted_foreign_control") for v in out.values()) or c["foreign_frames_accepted"]
    return 1 if bad else 0


def _merge(a: dict, b: dict) -> dict:
    out = dict(b)
    for k in ("datagrams", "crashes", "accepted_foreign_control", "accepted_control_from_companion",
              "racer_answers", "sitl_bad_packets", "sitl_rebound", "sitl_clients_evicted"):
        out[k] = a.get(k, 0) + b.get(k, 0)
    for k in ("by_kind", "sitl_ignored_control", "sitl_dropped_unparsed"):
        out[k] = dict(Counter(a.get(k, {})) + Counter(b.get(k, {})))
    out["completed_all"] = bool(a.get("completed_all", a.get("completed"))) and bool(b.get("completed"))
    out["max_error_m"] = max(x for x in (a.get("max_error_m"), b.get("max_error_m")) if x is not None) \
        if a.get("max_error_m") is not None or b.get("max_error_m") is not None else None
    return out


if __name__ == "__main__":
    sys.exit(main())
