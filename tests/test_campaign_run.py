"""Flights on Dask: resume by scenario hash, the worker-death retry, one real campaign end to end."""

from __future__ import annotations

import os
import uuid
from pathlib import Path

import pytest

pytest.importorskip("dask.distributed")
pytest.importorskip("pyarrow")

from companion.campaign.results import WALL_COLUMNS, make_row, read_results, write_table  # noqa: E402
from companion.campaign.run import keep_completed, make_client, run_flights  # noqa: E402
from companion.campaign.scenarios import load_fields, scenario, scenario_hash  # noqa: E402
from companion.campaign.spec import spec_from_dict  # noqa: E402

SPEC = {"name": "r", "missions": ["flat-rectangle"], "flights": 8, "seed": 2, "cut_s": 5.0,
        "wind": {"speed_m_s": [0.0, 2.0]}}


def _fake_fly(s, out, keep, transport, calls_dir):
    """A flight whose figures are a function of the scenario (no SITL): clearance = wind speed."""
    Path(calls_dir, f"{scenario_hash(s)}-{uuid.uuid4().hex}").touch()
    w = s["overrides"]["sim"]["wind"]["mean_enu_m_s"]
    speed = (w[0] ** 2 + w[1] ** 2) ** 0.5
    rep = {"completed": speed < 1.5, "crashed": speed >= 1.5, "crash": {"text": "blown away"},
           "replanning": {"min_clearance_m": 2.0 - speed}, "tracking": {"max_error_m": speed / 100}}
    return make_row(s, rep, None, wall_s=float(len(os.listdir(calls_dir))))


@pytest.fixture(scope="module")
def client():
    from dask.distributed import Client

    c = Client(processes=False, n_workers=1, threads_per_worker=2, dashboard_address=None)
    yield c
    c.close()


def test_resume_flies_only_what_is_missing_and_gives_the_same_table(tmp_path, client):
    spec = spec_from_dict(SPEC, "r.yaml")
    scen = [scenario(spec, load_fields(spec), i) for i in range(8)]
    calls = tmp_path / "calls"
    calls.mkdir()

    def fly(s, out, keep, transport):
        return _fake_fly(s, out, keep, transport, calls)

    a, b = tmp_path / "a", tmp_path / "b"
    rows_a = run_flights(client, scen, a, fly=fly)
    assert len(os.listdir(calls)) == 8 and len(read_results(a / "results")) == 8
    # interrupted run: b has flown 5 of them; two results then lost as well
    run_flights(client, scen[:5], b, fly=fly)
    for s in scen[1:3]:
        (b / "results" / f"{scenario_hash(s)}.json").unlink()
    before = len(os.listdir(calls))
    rows_b = run_flights(client, scen, b, fly=fly, done=read_results(b / "results"))
    assert len(os.listdir(calls)) - before == 5          # scenarios 1, 2 (deleted) and 5, 6, 7 (never flown)
    assert [r["hash"] for r in rows_b] == [scenario_hash(s) for s in scen]
    # a rerun of a finished campaign flies nothing
    before = len(os.listdir(calls))
    run_flights(client, scen, b, fly=fly, done=read_results(b / "results"))
    assert len(os.listdir(calls)) == before
    import pyarrow.parquet as pq

    write_table(rows_a, a)
    write_table(rows_b, b)
    ta = pq.read_table(a / "results.parquet").drop_columns(list(WALL_COLUMNS))
    tb = pq.read_table(b / "results.parquet").drop_columns(list(WALL_COLUMNS))
    assert ta.equals(tb) and ta.num_rows == 8


def test_keep_sample_is_a_fraction_of_hashes():
    hs = [f"{i * 2654435761 % 2**32:08x}" + "0" * 8 for i in range(2000)]
    kept = sum(keep_completed(h, 0.1) for h in hs)
    assert 150 <= kept <= 250
    assert not any(keep_completed(h, 0.0) for h in hs) and all(keep_completed(h, 1.0) for h in hs)


@pytest.mark.slow
def test_a_worker_that_dies_loses_only_its_flight_retried_once(tmp_path):
    spec = spec_from_dict(SPEC, "r.yaml")
    scen = [scenario(spec, load_fields(spec), i) for i in range(3)]
    marker_dir = str(tmp_path)

    def fly(s, out, keep, transport):
        import os as _os
        from pathlib import Path as _P

        from companion.campaign.results import make_row as _row

        m = _P(marker_dir, f"died-{s['scenario']}")
        if s["scenario"] == 0 and not m.exists():      # dies once, then flies
            m.touch()
            _os._exit(3)
        if s["scenario"] == 1:                          # dies every time
            import uuid as _u
            _P(marker_dir, f"died-1-{_u.uuid4().hex}").touch()
            _os._exit(3)
        return _row(s, {"completed": True, "crashed": False}, None, 0.0)

    client = make_client(workers=1)
    try:
        rows = run_flights(client, scen, tmp_path / "out", fly=fly)
    finally:
        cluster = client.cluster
        client.close()
        cluster.close()
    by = {r["scenario"]: r for r in rows}
    assert by[0]["outcome"] == "completed" and (tmp_path / "died-0").exists()
    assert by[2]["outcome"] == "completed"
    assert by[1]["outcome"] == "failed" and "KilledWorker" in by[1]["reason"]
    assert len(list(tmp_path.glob("died-1-*"))) == 2    # the first try and one retry


@pytest.mark.slow
def test_small_real_campaign_end_to_end(tmp_path, capsys):
    """Two real flights (flat-rectangle, 3 s cut) through a LocalCluster of 2 workers."""
    import pyarrow.parquet as pq

    from companion.cli import main

    root = Path(__file__).resolve().parents[1]
    out = tmp_path / "c"
    assert main(["campaign", str(root / "campaigns" / "smoke.yaml"), "--out", str(out), "--flights", "2",
                 "--cut", "3", "--workers", "2", "--quiet"]) == 0
    t = pq.read_table(out / "results.parquet").to_pylist()
    assert [r["scenario"] for r in t] == [0, 1]
    assert all(r["outcome"] == "completed" for r in t)
    # no obstacle, light wind: mm-level tracking, path 3 s long
    assert all(0 < r["tracking_max_error_m"] < 0.05 for r in t)
    for r in t:
        assert (out / "scenarios" / f"{r['scenario']:04d}.yaml").exists()
        assert r["hash"] == scenario_hash(__import__("yaml").safe_load(
            (out / "scenarios" / f"{r['scenario']:04d}.yaml").read_text()))
    assert "data:image/png;base64," in (out / "summary.html").read_text()
    assert (out / "summary.md").exists() and (out / "results.csv").exists()


def test_progress_line_counts_failures_and_eta():
    import io

    from companion.campaign.run import CampaignProgress

    buf = io.StringIO()
    p = CampaignProgress(total=10, skipped=2, stream=buf)
    p.t0 -= 60.0                    # 60 s elapsed for the 2 flights flown in this run
    p.update({"outcome": "completed"})
    p.update({"outcome": "crashed"})
    last = buf.getvalue().splitlines()[-1]
    assert "4/10 flights (2 from earlier runs)" in last and "crashed 1" in last
    assert "ETA 3m00s" in last      # 30 s per flight flown here, 6 left
    quiet = io.StringIO()
    q = CampaignProgress(total=3, skipped=0, stream=quiet, enabled=False)
    q.update({"outcome": "failed"})
    assert quiet.getvalue() == ""
