"""The numeric environment's fingerprint (companion/flight/environment.py) and how two compare."""

from __future__ import annotations

import json
import sys

import numpy
import scipy

from companion.flight.environment import FP_FLAGS, differences, fingerprint
from companion.flight.setup_record import SETUP_TEXT_ID, parse_setup, setup_chunks


def test_fingerprint_names_this_process_and_survives_the_setup_record():
    fp = fingerprint()
    assert fp["format"] == "env/1"
    assert fp["numpy"] == numpy.__version__ and fp["scipy"] == scipy.__version__
    assert fp["python"].endswith(".".join(map(str, sys.version_info[:3])))
    assert set(fp["cpu"]["flags"]) <= set(FP_FLAGS)
    assert fp["blas_kernels"] and all(isinstance(k, str) for k in fp["blas_kernels"])
    # a copy each time: a caller editing it does not change the next one
    fp["cpu"]["model"] = "edited"
    assert fingerprint()["cpu"]["model"] != "edited"
    # through the chunked STATUSTEXT and back, inside a setup record, unchanged
    setup = {"format": "companion-setup/1", "environment": fingerprint()}
    chunks = setup_chunks(setup)
    assert len(chunks) < 64
    back = parse_setup([(t.decode(), SETUP_TEXT_ID, k) for t, k in chunks])
    assert back == json.loads(json.dumps(setup)) and differences(back["environment"], fingerprint()) == []


def test_differences_name_the_keys_and_an_unknown_environment():
    here = fingerprint()
    assert differences(None, here) == ["unknown"] and differences("x", here) == ["unknown"]
    other = json.loads(json.dumps(here))
    other["cpu"]["vendor"] = "AuthenticAMD"
    other["cpu"]["flags"] = [f for f in other["cpu"]["flags"] if f != "avx512f"] + ["fma4"]
    other["numpy"] = "1.26.4"
    assert differences(other, here) == ["cpu.flags", "cpu.vendor", "numpy"]
    del other["scipy_blas"]
    assert "scipy_blas" in differences(other, here)


def test_the_flight_setup_records_the_environment():
    from companion.bundled import missions_dir
    from companion.commands.fly import flight_setup
    from mavcore.mission import load_mission

    mission = load_mission(missions_dir() / "flat-rectangle" / "mission.yaml")
    setup = flight_setup(mission, None, "companion", None, {})
    assert setup["environment"] == fingerprint()
