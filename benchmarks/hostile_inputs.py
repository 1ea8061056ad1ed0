"""Every hostile input file of tests/hostile_corpus.py as a real ``companion``
subprocess (issue 19's target for file inputs): under a 1 GiB address-space
limit (RLIMIT_AS) and a wall-clock timeout, each must end within the timeout
with at most 500 MB peak RSS, exactly one line on stderr, exit code 2 and
nothing written in its working directory. Prints one row per case (wall and
CPU seconds, peak RSS from ``os.wait4``) and a summary; exit code 1 if any
case fails.

    python benchmarks/hostile_inputs.py [--timeout 5] [-k SUBSTRING] [--only ID,...] [--markdown]

Wall time includes the interpreter's start and the imports (about 1 s idle),
so on a loaded machine it is the CPU column that shows the work bounded.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from hostile_corpus import CASES, check_base, make_base, run_limited, tree  # noqa: E402

MAX_RSS_BYTES = 500e6


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--timeout", type=float, default=5.0, help="wall-clock limit per case (s)")
    ap.add_argument("-k", default="", help="only the cases whose id contains this")
    ap.add_argument("--only", default="", help="only these case ids (comma-separated)")
    ap.add_argument("--markdown", action="store_true", help="print the table as markdown")
    args = ap.parse_args(argv)
    only = set(filter(None, args.only.split(",")))
    cases = [c for c in CASES if args.k in c.id and (not only or c.id in only)]
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = make_base(Path(tmp) / "base")
        check_base(base)
        for i, case in enumerate(cases):
            d = Path(tmp) / f"case{i}"
            d.mkdir()
            argv_ = case.build(d, base)
            before = tree(d)
            rc, err, wall, cpu, rss, timed_out = run_limited(argv_, d, case.env, timeout_s=args.timeout)
            lines = err.count("\n")
            written = tree(d) != before
            problems = [p for p, bad in (("timeout", timed_out), ("exit", rc != 2), ("lines", lines != 1),
                                         ("rss", rss > MAX_RSS_BYTES), ("written", written),
                                         ("needle", case.needle not in err), ("traceback", "Traceback" in err))
                        if bad]
            rows.append((case.id, argv_[0], rc, lines, wall, cpu, rss / 1e6, "ok" if not problems else
                         "FAIL " + ",".join(problems), err.strip().splitlines()[-1][:110] if err.strip() else ""))
            shutil_rmtree(d)
    sep = " | " if args.markdown else "  "
    head = ("case", "command", "exit", "lines", "wall s", "cpu s", "RSS MB", "verdict")
    if args.markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "---|" * len(head))
    else:
        print(f"{head[0]:34s}{sep}{head[1]:7s}{sep}exit{sep}lines{sep}wall s{sep} cpu s{sep}RSS MB{sep}verdict")
    for cid, cmd, rc, lines, wall, cpu, rss, verdict, _ in rows:
        cells = (f"{cid:34s}", f"{cmd:7s}", f"{rc:4d}", f"{lines:5d}", f"{wall:6.2f}", f"{cpu:6.2f}", f"{rss:6.0f}",
                 verdict)
        print(("| " + " | ".join(c.strip() for c in cells) + " |") if args.markdown else sep.join(cells))
    bad = [r for r in rows if r[7] != "ok"]
    walls, cpus, rsss = [r[4] for r in rows], [r[5] for r in rows], [r[6] for r in rows]
    print(f"\n{len(rows)} cases, {len(rows) - len(bad)} ok, {len(bad)} failed; "
          f"wall s median {statistics.median(walls):.2f} "
          f"max {max(walls):.2f}; cpu s median {statistics.median(cpus):.2f} max {max(cpus):.2f}; "
          f"peak RSS MB median {statistics.median(rsss):.0f} max {max(rsss):.0f}")
    for r in bad:
        print(f"  {r[0]}: {r[7]}: {r[8]}")
    return 1 if bad else 0


def shutil_rmtree(d: Path) -> None:
    import shutil

    shutil.rmtree(d, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
