"""Per-call CPU cost (us, process_time) of the per-frame codec paths, run against a tree given as argv[1]
(issue 17 "h17-core": compare the branch point with mavcore.codec, interleaved)."""
import sys, time, os
root = sys.argv[1]; sys.path.insert(0, root)
from pymavlink.dialects.v20 import common as mavlink
try:
    from mavcore import codec as C; S = C
except ImportError:
    from companion.link import codec as C
    from sitl import codec as S
mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
N = 100000
args = S.highres_imu_args(123456, (0.1, 0.2, 9.8), (0.01, 0.02, 0.03), (0.2, 0.0, 0.4), 12.0)
pkt = S.PACK_HIGHRES_IMU.pack(mav, args) + S.PACK_LOCAL_POSITION_NED.pack(mav, S.local_position_ned_args(1000, (1, 2, 3), (0.1, 0.2, 0.3)))
hil = C.pack_hil_actuator_controls(1, 1, 191, 123456, (0.5, 0.5, 0.5, 0.5), True)
def t(f):
    c0 = time.process_time()
    for _ in range(N): f()
    return (time.process_time() - c0) / N * 1e6
r = {
 'sitl_pack_imu': t(lambda: S.PACK_HIGHRES_IMU.pack(mav, args)),
 'comp_split': t(lambda: C.split_datagram(pkt)),
 'comp_pack_hil': t(lambda: C.pack_hil_actuator_controls(1, 1, 191, 123456, (0.5, 0.5, 0.5, 0.5), True)),
 'sitl_decode_hil': t(lambda: S.decode_actuator_datagram(hil)),
}
print(' '.join(f'{k}={v:.3f}' for k, v in r.items()))
