"""The `adversary search` and `adversary search-report` subcommands (black-box scenario search)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rasterize.errors import InputError
from riskmap.infra.cli import add_config_options, add_run_options, config_from_args, positive_int
from riskmap.registry import SPEC_HELP


def _print_summary(summary: dict, out: str) -> None:
    share = summary["collision_share"]
    print(f"{summary['collisions']} of {summary['evaluations']} evaluations collided "
          f"({100 * share:.0f}%), {summary['failures']['counted']} of them valid, avoidable and at fault "
          f"({summary['failures']['unknown']} unclassified); {summary['evaluations'] - summary['feasible']} infeasible; "
          f"failure diversity {summary['failure_diversity']}; results in {out}")
    best = summary["least_altered_failure"]
    if best:
        print(f"least-altered failure (alteration {best['alteration']:.3f}): {best['description']}")


def _run_search(args: argparse.Namespace) -> int:
    from adversary.search.run import SearchConfig, search

    config = config_from_args(SearchConfig, args)
    _print_summary(search(config, Path(args.out), resume=args.resume, progress=not args.quiet,
                          backend=args.backend, address=args.address), args.out)
    return 0


def _run_report(args: argparse.Namespace) -> int:
    from adversary.search.report import write_report

    run_json = Path(args.out) / "run.json"
    if not run_json.exists():
        raise InputError(f"--out {args.out} holds no search run (no run.json); run `adversary search`")
    try:
        if "config" not in json.loads(run_json.read_text()):
            raise ValueError("no config")
    except (OSError, ValueError, TypeError):
        raise InputError(f"{run_json} is damaged (not the run.json of `adversary search`); run "
                         "`adversary search` again into a new --out") from None
    _print_summary(write_report(Path(args.out), frames=not args.no_frames), args.out)
    return 0


def add_parsers(subparsers) -> None:
    from adversary.search.run import ALGORITHMS, SearchConfig
    from adversary.search.scenarios import TEMPLATES

    p = subparsers.add_parser("search", help="NSGA-II or random search for scenarios where the ego "
                                             "collides")
    add_config_options(
        p, SearchConfig, "planner", "template", "algorithm", "pop", "gen", "seed", "episode_s", "workers",
        help={"planner": SPEC_HELP,
              "template": "the scenario family searched (its parameters are the search's variables)",
              "algorithm": "nsga2: NSGA-II; random: uniform random vectors that satisfy the "
                           "template's constraint (the baseline)",
              "seed": "seeds the search algorithm, the planner and the simulated scenes",
              "pop": "evaluations per generation",
              "gen": "generations", "episode_s": "simulated seconds per evaluation",
              "workers": "evaluation processes"},
        option_types={"pop": positive_int, "gen": positive_int, "workers": positive_int},
        choices={"template": sorted(TEMPLATES), "algorithm": ALGORITHMS})
    p.add_argument("--backend", default="local", choices=("local", "ray"),
                   help="local process pool, or Ray tasks (pip install 'riskmap-toolkit[ray]')")
    p.add_argument("--address", default=None, help="Ray cluster address (default: a local Ray)")
    p.add_argument("--out", required=True, help="directory for evaluations, summary and figures")
    add_run_options(p, _run_search, resume="continue a run in --out")
    p = subparsers.add_parser("search-report", help="rebuild the summary and figures of a search run")
    p.add_argument("--out", required=True, help="directory of a search run")
    p.add_argument("--no-frames", action="store_true", help="skip replaying the best failure")
    p.set_defaults(func=_run_report)
