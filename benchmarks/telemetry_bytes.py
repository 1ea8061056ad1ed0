"""Hash every byte the SITL's telemetry sends over 3000 frames, for a tree given as argv[1]
(h17-fin: the telemetry service must send what ``SitlServer`` sent before, byte for byte and in
order; compare the printed lines of two trees).

Three ``SitlServer``s (no sockets): PX4 and ArduCopter on flat-rectangle, PX4 on obstacle-tall (its
rangefinders' DISTANCE_SENSOR), each with two stand-in links that hash what they are handed, frame
boundaries included. At frame 10 the intervals change
(ODOMETRY every frame, ATTITUDE off, HEARTBEAT every third frame, DISTANCE_SENSOR at 50 Hz), at frame
1500 the frame is sent whole again (the late peer's resend). SYSTEM_TIME's wall epoch is pinned. Prints, per vehicle, the
links' hashes, the bytes and the frames.
"""
import hashlib
import sys
import time

root = sys.argv[1]
sys.path.insert(0, root)
time.time = lambda: 1.8e9          # SYSTEM_TIME's wall-clock epoch, the same in every run
from pymavlink.dialects.v20 import common as mavlink   # noqa: E402

from mavcore.mission import load_mission   # noqa: E402
from sitl.server import ServerConfig, SitlServer   # noqa: E402


class _Link:
    has_peer = True

    def __init__(self):
        self.mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
        self.hash = hashlib.sha256()
        self.n = self.frames = 0

    def begin_frame(self):
        self.hash.update(b"<")

    def end_frame(self):
        self.hash.update(b">")
        self.frames += 1

    def send_fast(self, packer, args):
        self._add(packer.pack(self.mav, args))

    def send(self, msg):
        self._add(msg.pack(self.mav))

    def reply(self, msg, addr=None):
        self.send(msg)

    def _add(self, b):
        self.hash.update(b)
        self.n += len(b)


for autopilot, mission in (("px4", "flat-rectangle"), ("ardupilot", "flat-rectangle"), ("px4", "obstacle-tall")):
    srv = SitlServer(load_mission(f"{root}/missions/{mission}/mission.yaml"), ServerConfig(autopilot=autopilot))
    srv.links = [_Link(), _Link()]
    period = srv.vehicle.sim.sensor_period_us
    for k in range(3000):
        if k == 10:
            for mid, iv in ((mavlink.MAVLINK_MSG_ID_ODOMETRY, period), (mavlink.MAVLINK_MSG_ID_ATTITUDE, -1),
                            (mavlink.MAVLINK_MSG_ID_HEARTBEAT, 3 * period),
                            (mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR, 20000)):
                srv.commands.handle(mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, (mid, iv, 0, 0, 0, 0, 0))
        if k == 1500:
            srv._resend_frame()
        srv.step_once()
    print(autopilot, mission, [link.hash.hexdigest()[:16] for link in srv.links], srv.links[0].n,
          srv.links[0].frames)
