"""The in-flight fault corpus of issue 19: output faults injected while
``companion fly`` flies the bundled SITL (a subprocess, lockstep, loopback UDP).

Usage::

    python scripts/inflight_faults.py [--only NAME ...] [--json OUT.json]

Each case flies ``flat-rectangle --cut 5`` and injects one fault when the SITL
says the vehicle is where the case wants it (flying, before arming, landing).
The target (issue 19): the vehicle ends on the ground (disarmed) or holding,
as the SITL itself reports it to a ground station (not the companion's
.tlog: that is what fails); a report is on disk (where asked, or in the
temporary directory, named on stderr); the exit code is 3 and stderr names
the fault; ``completed`` is false. Prints one row a case and exits 1 when a
case misses the target. About 20 s a case.

The fault seams are the ones of ``tests/test_output_faults_e2e.py``: the .tlog's
file object (``companion.link.tlog.open_tlog_file``) wrapped to fail with an
errno, or to swallow what it is given; and the file system itself (files and
directories deleted, replaced, truncated; a small tmpfs filled up, where
mounting is permitted).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import io
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from test_output_faults_e2e import AUTO_LAND, AUTO_LOITER, LAUNCH, MISSION, REACTION_S, Watch  # noqa: E402


class FailingFile:
    """The .tlog's file: once ``armed_event`` is set every write and flush fails with
    ``err``; with ``err`` None they are swallowed instead (a file that stops growing)."""

    def __init__(self, f, event: threading.Event, err: int | None) -> None:
        self.f, self.event, self.err = f, event, err

    def _gone(self) -> bool:
        if not self.event.is_set():
            return False
        if self.err is not None:
            raise OSError(self.err, os.strerror(self.err))
        return True

    def write(self, b):
        if self._gone():
            return len(b)
        return self.f.write(b)

    def flush(self):
        if not self._gone():
            self.f.flush()

    def fileno(self):
        return self.f.fileno()

    def close(self):
        self.f.close()


@dataclass
class Case:
    name: str
    when: str                 # flying, before_arming, landing
    fault: str                # what is done
    on_failure: str = "land"
    expect: str = "ground"    # ground (landed, disarmed), holding, never_armed


CASES = [
    Case("enospc-land", "flying", "enospc"),
    Case("enospc-hold", "flying", "enospc", "hold", "holding"),
    Case("eio-land", "flying", "eio"),
    Case("eio-hold", "flying", "eio", "hold", "holding"),
    Case("not-growing-land", "flying", "swallow"),
    Case("tlog-deleted-land", "flying", "unlink"),
    Case("tlog-deleted-hold", "flying", "unlink", "hold", "holding"),
    Case("tlog-replaced-land", "flying", "replace"),
    Case("tlog-truncated-land", "flying", "truncate"),
    Case("outdir-deleted-land", "flying", "rmtree"),
    Case("outdir-deleted-hold", "flying", "rmtree", "hold", "holding"),
    Case("report-dir-deleted", "flying", "rmtree_report"),
    Case("enospc-before-arming", "before_arming", "enospc", expect="never_armed"),
    Case("enospc-while-landing", "landing", "enospc"),
    Case("tmpfs-full-land", "flying", "fill"),
]


def _when(kind: str):
    if kind == "flying":
        return lambda s: s["armed"] and s["alt"] > 1.0
    if kind == "before_arming":
        return lambda s: not s["armed"]
    return lambda s: s["armed"] and s["mode"] == AUTO_LAND


def run_case(case: Case, work: Path) -> dict:
    from companion.cli import main
    from companion.link import tlog as tlog_mod
    from sitl.api import SitlProcess

    out, rdir, tmp = work / "out", work / "rep", work / "tmp"
    for d in (out, rdir, tmp):
        d.mkdir(parents=True)
    mounted = False
    if case.fault == "fill":
        r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=40m", "tmpfs", str(out)], capture_output=True)
        if r.returncode != 0:
            return {"case": case.name, "skipped": "mounting a tmpfs is not permitted"}
        mounted = True
    tlog = out / "flight.tlog"
    report = (rdir if case.fault == "rmtree_report" else out) / "report.json"
    event = threading.Event()
    real_open = tlog_mod.open_tlog_file
    errs = {"enospc": errno.ENOSPC, "eio": errno.EIO, "swallow": None}
    if case.fault in errs:
        err = errs[case.fault]
        tlog_mod.open_tlog_file = lambda p: FailingFile(real_open(p), event, err)

    def inject() -> None:
        f = case.fault
        if f in errs:
            event.set()
        elif f == "unlink":
            tlog.unlink()
        elif f == "replace":
            other = work / "other.tlog"
            other.write_bytes(b"\0" * 1000)
            os.replace(other, tlog)
        elif f == "truncate":
            os.truncate(tlog, 0)
        elif f == "rmtree":
            shutil.rmtree(out)
        elif f == "rmtree_report":
            shutil.rmtree(rdir)
        elif f == "fill":
            with open(out / "filler", "wb") as fh:
                try:
                    while True:
                        fh.write(b"\0" * (1 << 20))
                        fh.flush()
                except OSError:
                    pass

    old_tempdir = tempfile.tempdir
    tempfile.tempdir = str(tmp)
    ever_armed = {"v": False}
    when = _when(case.when)

    def watch_when(s):
        ever_armed["v"] |= s["armed"]
        return when(s)

    err_text = io.StringIO()
    try:
        with SitlProcess(MISSION, lockstep=True, start=LAUNCH) as sitl:
            watch = Watch(sitl.url, watch_when, inject)
            watch.start()
            try:
                with contextlib.redirect_stderr(err_text), contextlib.redirect_stdout(io.StringIO()):
                    rc = main(["fly", str(MISSION), "--connect", sitl.url, "--tlog", str(tlog), "--report",
                               str(report), "--quiet", "--cut", "5", "--on-failure", case.on_failure])
            except BaseException as exc:            # a traceback is a miss, not the end of the corpus
                rc = f"raised {type(exc).__name__}: {exc}"
            finally:
                watch.close()
    finally:
        tlog_mod.open_tlog_file = real_open
        tempfile.tempdir = old_tempdir
    fallbacks = sorted(tmp.glob("companion-report-*.json"))
    where = fallbacks[0] if fallbacks else report
    rep = json.loads(where.read_text()) if where.is_file() else None
    st = watch.state
    if case.expect == "holding":
        dt = watch.mode_after(watch.fired_at or 0.0, AUTO_LOITER)
        state_ok = st["armed"] and st["alt"] > 1.0 and dt is not None and dt < REACTION_S
        end = f"holding {st['alt']:.1f} m" if st["armed"] else "on the ground"
    elif case.expect == "never_armed":
        state_ok = not ever_armed["v"] and not st["armed"]
        end = "never armed" if not ever_armed["v"] else "armed!"
    else:
        land_ok = True
        if case.when == "flying" and case.fault != "rmtree_report":
            dt = watch.mode_after(watch.fired_at or 0.0, AUTO_LAND)
            land_ok = dt is not None and dt < REACTION_S
        state_ok = land_ok and not st["armed"] and st["alt"] < 0.3
        end = "landed, disarmed" if not st["armed"] and st["alt"] < 0.3 else f"armed at {st['alt']:.1f} m"
    stderr = err_text.getvalue()
    named = rep is not None and bool(rep["faults"]) and rep["faults"][0]["detail"] in stderr
    row = {
        "case": case.name, "fired": watch.fired_at is not None, "rc": rc, "end": end,
        "report": None if rep is None else ("fallback (named)" if fallbacks and str(fallbacks[0]) in stderr
                                            else "fallback (NOT named)" if fallbacks else "as asked"),
        "completed": None if rep is None else rep["completed"],
        "fault": None if rep is None or not rep["faults"] else rep["faults"][0]["detail"].split(": ", 1)[-1],
        "phase": None if rep is None else f"{rep['phase']} -> {rep['end_phase']}",
        "traceback": "Traceback" in stderr or isinstance(rc, str),
    }
    row["ok"] = bool(row["fired"] and rc == 3 and state_ok and rep is not None and not rep["completed"]
                     and named and not row["traceback"] and row["report"] != "fallback (NOT named)")
    if mounted:
        subprocess.run(["umount", "-l", str(out)], capture_output=True)
    return row


def main_(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", default=None, metavar="NAME")
    ap.add_argument("--json", default=None, metavar="OUT.json")
    args = ap.parse_args(argv)
    cases = [c for c in CASES if args.only is None or c.name in args.only]
    rows = []
    with tempfile.TemporaryDirectory(prefix="inflight-faults-") as d:
        for c in cases:
            row = run_case(c, Path(d) / c.name)
            rows.append(row)
            print(json.dumps(row), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(rows, indent=2) + "\n")
    missed = [r["case"] for r in rows if not r.get("ok") and "skipped" not in r]
    print(f"{len(rows) - len(missed)}/{len(rows)} cases met the target" + (f"; missed: {missed}" if missed else ""))
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main_())
