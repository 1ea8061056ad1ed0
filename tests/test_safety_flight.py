"""The guard in a short in-process flight (issue 15): the crate of obstacle-low moved
into the first corridor (as tests/test_replan_e2e.py), 14 s of trajectory.

Every reference went through the guard (one check per frame of the flying phases),
the plan and the take-off were checked whole before arming and the rejoin's new
trajectory when it appeared, the landing at the end was checked; none was refused,
and the true clearance held.
"""

from __future__ import annotations

import json

import pytest

from companion.cli import main
from companion.bundled import missions_dir

OBSTACLE_XY = (17.0, 8.75)


@pytest.fixture(scope="module")
def crate_flight(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("guard-flight")
    src = missions_dir() / "obstacle-low" / "mission.yaml"
    text = src.read_text().replace("../flat-rectangle/", str(missions_dir() / "flat-rectangle") + "/")
    old = "{type: box, x: 7.0, y: 6.25,"
    assert old in text
    text = text.replace(old, f"{{type: box, x: {OBSTACLE_XY[0]}, y: {OBSTACLE_XY[1]},")
    path = tmp / "crate.yaml"
    path.write_text(text)
    out = tmp / "out"
    rc = main(["demo", "--mission", str(path), "--cut", "14", "--transport", "inproc", "--out", str(out),
               "--no-plots", "--quiet"])
    return rc, json.loads((out / "report.json").read_text())


def test_every_reference_of_an_avoiding_flight_passed_the_guard(crate_flight):
    rc, rep = crate_flight
    assert rc == 0 and rep["completed"], rep["violation"]
    g = rep["guard"]
    actions = [e["action"] for e in rep["replanning"]["event_list"]]
    assert "avoid" in actions and "rejoin" in actions
    # plan + take-off before arming, and one per new trajectory of the replanner (the rejoin)
    assert g["trajectories_checked"] == 2 + actions.count("rejoin") + actions.count("reroute")
    # one check per frame from the take-off to the landing command (250 Hz)
    flying_s = rep["sim_time_s"] - 20.0
    assert g["samples_checked"] >= 250 * min(flying_s, rep["trajectory_duration_s"])
    assert g["landings_checked"] == 1 and g["landings_refused"] == 0
    assert g["refusals"] == 0 and not g["engaged"]
    assert rep["replanning"]["min_clearance_m"] >= 0.5
