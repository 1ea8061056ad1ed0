"""The row compass against the true heading error, along one flight (issue 15, BENCHMARKS "h15-compass").

Usage::

    python benchmarks/trace_heading.py SCENARIO_OR_MISSION OUT [PERIOD_S]

Flies ``companion demo`` in process (``--transport inproc``; a campaign's
scenario file, or a mission YAML) and, every ``PERIOD_S`` of vehicle time
(default 3), prints the vehicle's true heading, the error of the pose that
places the rangefinder readings (estimate minus truth, about the vertical,
deg; the truth read from the simulation running in the same process), the
row compass's correction (``HeadingBias.estimate_rad``, added to every
beam) and the residual (error + correction: 0 when the compass undoes the
error), with the replanner's mode. Reads the simulation's state; changes
nothing the flight does.
"""

from __future__ import annotations

import math
import sys

import numpy as np

from companion import cli
from companion.replan import replanner as rm
from sitl import sim as S


def main(argv: list[str]) -> int:
    src, out = argv[0], argv[1]
    period = float(argv[2]) if len(argv) > 2 else 3.0
    sims, last = [], [-math.inf]
    init = S.Simulation.__init__

    def _init(self, *a, **k):
        init(self, *a, **k)
        sims.append(self)

    S.Simulation.__init__ = _init
    step = rm.Replanner.step

    def _step(self, t_s, pos, vel):
        ref = step(self, t_s, pos, vel)
        pose = self.poses.at(t_s)
        if t_s - last[0] >= period and pose is not None and sims:
            last[0] = t_s
            Rt = np.asarray(sims[-1].truth.R)
            E = np.asarray(pose.R).reshape(3, 3) @ Rt.T
            err = math.degrees(math.atan2(E[1, 0], E[0, 0]))
            est = math.degrees(self.heading.estimate_rad or 0.0)
            print(f"t={t_s:7.2f} s heading={math.degrees(math.atan2(Rt[1, 0], Rt[0, 0])):7.1f} "
                  f"error={err:6.2f} compass={est:6.2f} residual={err + est:6.2f} deg mode={self.mode}", flush=True)
        return ref

    rm.Replanner.step = _step
    flag = "--scenario" if "campaign:" in open(src, encoding="utf-8").read(4096) else "--mission"
    return cli.main(["demo", flag, src, "--transport", "inproc", "--no-plots", "-q", "--out", out])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
