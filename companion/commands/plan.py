"""``companion plan MISSION.yaml -o plan.json [--samples HZ] [--plot plan.png]
[--qgc plan.plan] [--waypoints plan.waypoints] [--geojson plan.geojson] [--kml plan.kml]
[--html map.html]``.

Plans the mission (``companion.planner.plan_mission``), prints a short
summary and writes the outputs. Every output is rendered in memory first and
written only when the whole plan succeeded, each through a temporary file
in the target directory and ``os.replace``: bad input leaves nothing behind.
plan.json is encoded last, so that its ``timings_s`` can hold ``write``
(rendering every output, plan.json's encoding included) and ``wall`` (since
the process started: start-up, imports, planning, rendering; only the copy
of the bytes to disk comes after it, and the printed ``wall`` includes it).
"""

from __future__ import annotations

import errno
import math
import os
import sys
import tempfile
import time
from pathlib import Path

from mavcore.errors import InputError
from ..process_clock import process_wall_s


def add_arguments(parser) -> None:
    parser.add_argument("mission", help="mission YAML file")
    parser.add_argument("-o", "--output", required=True, metavar="PLAN.json", help="plan.json to write")
    parser.add_argument("--samples", "--sample-hz", dest="samples", type=float, default=None, metavar="HZ",
                        help="also store the trajectory sampled at HZ in plan.json (default: only its exact "
                             "polynomial pieces)")
    parser.add_argument("--plot", metavar="PLAN.png", help="figure of the plan (needs the plot extra)")
    parser.add_argument("--qgc", metavar="PLAN.plan", help="QGroundControl .plan export of the way-points")
    parser.add_argument("--waypoints", metavar="PLAN.waypoints", help='"QGC WPL 110" export of the way-points')
    parser.add_argument("--geojson", metavar="PLAN.geojson",
                        help="GeoJSON (WGS 84) of the path, sorties, launch point, fence and rows (docs/maps.md)")
    parser.add_argument("--kml", metavar="PLAN.kml", help="KML of the same layers as --geojson")
    parser.add_argument("--html", metavar="MAP.html", help="self-contained HTML map of the plan (no network)")


def write_atomically(outputs: dict[str, bytes]) -> None:
    """Write every ``path -> bytes`` through a temporary file and ``os.replace``.

    All temporaries are written first; only then are they renamed, so a
    failure (bad directory, disk full) leaves none of the outputs.
    """
    temps: list[tuple[str, str]] = []
    umask = os.umask(0)
    os.umask(umask)
    path = "output"
    try:
        for path, data in outputs.items():
            target = Path(path)
            fd, tmp = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp",
                                       dir=str(target.parent if str(target.parent) else "."))
            temps.append((tmp, path))
            os.fchmod(fd, 0o666 & ~umask)   # mkstemp makes 0600; give the usual permissions
            with os.fdopen(fd, "wb") as f:
                f.write(data)
        # A rename onto a directory fails; find it before any rename, so that no
        # output is replaced when another one cannot be.
        for tmp, path in temps:
            if Path(path).is_dir():
                raise IsADirectoryError(errno.EISDIR, os.strerror(errno.EISDIR), path)
        for tmp, path in temps:
            os.replace(tmp, path)
        temps.clear()
    except OSError as exc:
        # Name the output the user gave, never the temporary.
        raise InputError(path, f"cannot write: {exc.strerror or exc}") from None
    finally:
        for tmp, _ in temps:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def run(args) -> int:
    # Cheap checks before any work, so that a bad option costs nothing.
    if args.samples is not None and not (math.isfinite(args.samples) and args.samples > 0):
        raise InputError("--samples", f"must be a positive number of Hz, got {args.samples}")
    plot_fmt = None
    if args.plot:
        from ..plot import supported_formats   # raises a one-line InputError without matplotlib
        plot_fmt = Path(args.plot).suffix.lower().lstrip(".") or "png"
        if plot_fmt not in supported_formats():
            raise InputError(args.plot, f"unsupported figure format {plot_fmt!r} (use .png, .pdf, .svg, ...)")
    outputs = [p for p in (args.output, args.plot, args.qgc, args.waypoints, args.geojson, args.kml, args.html) if p]
    if len(set(map(os.path.abspath, outputs))) != len(outputs):
        raise InputError("command line", "the same file is given for two outputs")
    for p in outputs:
        parent = Path(p).parent
        if not parent.is_dir():
            raise InputError(p, f"cannot write: directory {str(parent)!r} does not exist")
        if Path(p).is_dir():
            # Checked up front: the final renames cannot be undone one by one.
            raise InputError(p, "cannot write: is a directory")

    from ..long_lived import imports_kept

    with imports_kept(args.process_exits):
        from mavcore.mission import load_mission
        from ..plan_io import (field_fence, flight_items, plan_json_text, plan_to_json_dict, qgc_plan_text,
                               qgc_wpl_text, sortie_file)
        from ..planner import plan_mission

    mission = load_mission(args.mission)
    plan = plan_mission(mission)
    t_render = time.perf_counter()
    doc = plan_to_json_dict(plan, mission, args.samples)
    files = {args.output: b""}         # first in the summary; encoded last (its timings)
    if args.qgc or args.waypoints:
        # one flight-ready mission per sortie (``<stem>-sortie<k>`` when there are several)
        fence = field_fence(plan, mission)
        sorties = plan.sorties.sorties
        for s in sorties:
            items = flight_items(plan, mission, s, fence)
            if args.qgc:
                files[sortie_file(args.qgc, s.index, len(sorties))] = \
                    qgc_plan_text(items, mission.flight.speed_m_s).encode("utf-8")
            if args.waypoints:
                files[sortie_file(args.waypoints, s.index, len(sorties))] = qgc_wpl_text(items).encode("utf-8")
    if args.plot:
        from ..plot import render_plan
        files[args.plot] = render_plan(plan, fmt=plot_fmt, title=f"{mission.name}")
    if args.geojson or args.kml or args.html:
        from ..map_layers import plan_layers

        layers = plan_layers(plan, mission)
        if args.geojson:
            from ..geo_export import geojson_text
            files[args.geojson] = geojson_text(layers).encode("utf-8")
        if args.kml:
            from ..geo_export import kml_text
            files[args.kml] = kml_text(layers).encode("utf-8")
        if args.html:
            from ..html_map import html_map_text
            files[args.html] = html_map_text(layers, f"{mission.name}: plan").encode("utf-8")
    files[args.output] = plan_json_text(doc, t_render).encode("utf-8")
    from ..plan_twin import twin_bytes, twin_path

    twin = twin_bytes(doc, files[args.output])      # a large plan's binary twin (format 2.1)
    if twin is not None:
        files[twin_path(args.output)] = twin
    write_atomically(files)

    for w in plan.warnings:
        print(f"warning: {w}", file=sys.stderr)
    st, tm = plan.stats, plan.timings_s
    print(f"{mission.name}: {st.n_waypoints} way-points, path {st.path_length_m:.1f} m, "
          f"duration {st.duration_s:.1f} s, coverage {100 * st.coverage_fraction:.1f} %, "
          f"orientation {st.orientation_deg:.1f} deg")
    print(f"  max speed {st.max_speed_m_s:.2f} m/s, max accel {st.max_accel_m_s2:.2f} m/s^2, "
          f"way-point residual {100 * st.waypoint_residual_m:.1f} cm")
    sp = plan.sorties
    worst = max(sp.sorties, key=lambda x: x.energy.energy_wh)
    print(f"  {len(sp.sorties)} sortie(s) from ({sp.launch_xy_m[0]:.1f}, {sp.launch_xy_m[1]:.1f}) m: "
          f"{sp.total_energy_wh:.0f} Wh, {sp.total_duration_s / 60:.1f} min in all; the largest "
          f"{worst.energy.energy_wh:.1f} Wh of {mission.energy.usable_wh:.1f} Wh usable, "
          f"{max(x.n_items for x in sp.sorties)} mission items (vehicle holds {mission.energy.max_mission_items})")
    print(f"  timings: load {tm.load:.3f} s, coverage {tm.coverage:.3f} s, "
          f"trajectory {tm.trajectory:.3f} s, total {tm.total:.3f} s, write {doc['timings_s']['write']:.3f} s, "
          f"wall {process_wall_s():.3f} s")
    print(f"  wrote {', '.join(files)}")
    return 0
