"""Command-line arguments that scripts share (the ``wheelloader`` command's own are in :mod:`wheelloader.cli`).

* the planner's opt-in physics of the adaptation benchmarks (``benchmarks/adaptation.py`` and
  ``benchmarks/plant_adaptation.py``): :func:`add_planner_physics_arguments`, :func:`planner_physics`.
"""

from __future__ import annotations

import argparse
import math
from typing import Any


def add_planner_physics_arguments(parser: argparse.ArgumentParser, scope: str) -> None:
    """``--end-blade-angle DEG`` (with ``--curl-out-intervals K``), ``--heel-clearance M`` and ``--cut-angle DEG``
    (all off by default), and ``--midpoints on|off`` (default the loop's);
    ``scope`` says which strategies plan with them (help text)."""
    parser.add_argument("--end-blade-angle", type=float, default=None, metavar="DEG",
                        help=f"the planner's opt-in smallest blade angle at the end [deg], {scope} (default: off)")
    parser.add_argument("--curl-out-intervals", type=int, default=0, metavar="K",
                        help="with --end-blade-angle: the plan's last K of its 40 intervals, in which the bucket "
                             "curls out of the pile (the tip may leave the soil; the heel clearance still holds; "
                             "default 0)")
    parser.add_argument("--heel-clearance", type=float, default=None, metavar="M",
                        help=f"the planner's opt-in heel clearance [m], {scope} (default: off)")
    parser.add_argument("--cut-angle", type=float, default=None, metavar="DEG",
                        help=f"the planner's opt-in cutting cone [deg], {scope} (default: off)")
    parser.add_argument("--midpoints", choices=("on", "off"), default=None,
                        help="the loop's plan constrains forces and validity at the intervals' midpoints too "
                             "(default: the loop's, wheelloader.adaptation.LOOP_PLANNER_MIDPOINTS; off with --mpc)")


def planner_physics(args: argparse.Namespace) -> dict[str, Any]:
    """Those settings as ``PlannerOptions`` keywords (angles in radians; None: off)."""
    radians = (lambda deg: None if deg is None else math.radians(deg))  # noqa: E731
    return {"cut_angle": radians(args.cut_angle), "heel_clearance": args.heel_clearance,
            "end_blade_angle": radians(args.end_blade_angle), "curl_out_intervals": args.curl_out_intervals,
            "midpoints": None if args.midpoints is None else args.midpoints == "on"}
