"""`adversary export`: attacked scenes of an `adversary attack` run, or of a stress-test campaign's
crash jobs (adversary.export.campaign), as files other tools read."""

from __future__ import annotations

import argparse
from pathlib import Path

from riskmap.infra.cli import add_run_options


def _run_export(args: argparse.Namespace) -> int:
    from adversary.export.campaign import export_campaign, is_campaign
    from adversary.export.commonroad import export_run
    from rasterize.errors import InputError

    if is_campaign(Path(args.run)):
        if args.scene or args.scenes:
            flag = "--scene" if args.scene else "--scenes"
            raise InputError(f"{flag} is for `adversary attack` runs; --run {args.run} is a campaign: name "
                             "its jobs with --job JOB_ID")
        index = export_campaign(Path(args.run), Path(args.out), args.format, only_failures=args.only_failures,
                                resume=args.resume, jobs=tuple(args.job or ()), plot=args.plot,
                                progress=not args.quiet)
        _print_exported(index, "jobs", args.out)
        return 0
    if args.job:
        raise InputError(f"--job is for campaign directories; --run {args.run} is not one (no campaign.json "
                         "and records/): name an attack run's scenes with --scene NAME")
    index = export_run(Path(args.run), Path(args.out), args.format, only_failures=args.only_failures,
                       resume=args.resume, scenes=Path(args.scenes) if args.scenes else None,
                       names=tuple(args.scene or ()), plot=args.plot, progress=not args.quiet)
    _print_exported(index, "scenes", args.out)
    return 0


def _print_exported(index: dict, what: str, out: str) -> None:
    """An export's one summary line: how many `what` (jobs, scenes) it wrote and skipped, and where
    its index says which and why."""
    print(f"{len(index['exported'])} {what} exported to {out} ({len(index['skipped'])} skipped; "
          f"see {Path(out) / 'index.json'})")


def add_parsers(subparsers) -> None:
    from adversary.export.commonroad import FORMATS

    p = subparsers.add_parser("export", help="write the attacked scenes of an `adversary attack` run or "
                                             "of a stress-test campaign's crash jobs as CommonRoad scenarios")
    p.add_argument("--run", required=True, help="the --out folder of an `adversary attack` run, or a "
                                                "campaign directory of `adversary stress-test`")
    # not argparse choices: an unknown format is one line naming the formats, like every bad input
    p.add_argument("--format", required=True, help=f"output format: {', '.join(FORMATS)}")
    p.add_argument("--out", required=True, help="folder for <scene>.xml + <scene>.json (+ .png); for a "
                                                "campaign's jobs <job_id>.xml ...")
    p.add_argument("--only-failures", action="store_true",
                   help="only scenes in which the ego collided from t0 (the judge's failures)")
    p.add_argument("--scenes", default=None,
                   help="the run's scene folder (default: the one its run.json names)")
    p.add_argument("--scene", action="append", default=None, metavar="NAME",
                   help="export only this scene (repeatable), e.g. scene_00092")
    p.add_argument("--job", action="append", default=None, metavar="JOB_ID",
                   help="a campaign: export only this job (repeatable); its id as in records/JOB_ID.json")
    p.add_argument("--plot", action="store_true",
                   help="also draw each scene with commonroad-io's renderer at the collision step "
                        "(<scene>.png)")
    add_run_options(p, _run_export, resume="continue an export into the same --out")
