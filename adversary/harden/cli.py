"""`adversary harden`: the planner fine-tuned on the attacks that beat it (`adversary.harden.loop`),
and `adversary harden-report`, the page that shows the rounds."""

from __future__ import annotations

import argparse
from pathlib import Path

from riskmap.infra.cli import QUIET_HELP, add_config_options, config_from_args, positive_int


def _run_harden(args: argparse.Namespace) -> int:
    from adversary.harden.loop import HardenConfig, harden
    from adversary.harden.report import write_report

    config = config_from_args(HardenConfig, args)
    summary = harden(config, resume=args.resume, progress=not args.quiet)
    page = write_report(Path(config.out))
    for entry in summary["rounds"]:
        judged = entry["judged"].get("attack")
        if judged:
            print(f"round {entry['round']}: fresh CRASH {judged['collisions']}/{judged['scenes']} on held-out scenes")
    print(f"report: {page}")
    return 0


def _run_report(args: argparse.Namespace) -> int:
    from adversary.harden.report import write_report

    print(write_report(Path(args.run)))
    return 0


HELP = {
    "checkpoint": "risk-map planner checkpoint to harden (round 0)",
    "scenes": "training attack scenes (`adversary scenes`)",
    "natural": "the natural dataset the checkpoint was trained on (`riskmap collect`)",
    "out": "run directory",
    "rounds": "hardening rounds",
    "count": "training scenes attacked per round",
    "natural_share": "share of natural windows among a round's training windows (0: attacks only)",
    "epochs": "fine-tuning epochs per round",
    "lr": "fine-tuning learning rate",
    "uncertainty_weight": "v of the IRL loss while fine-tuning (default: the checkpoint's)",
    "risk_goal_threshold": "fine-tune (and plan) with the risk-limited goal: the goal is held short on the route "
                           "where the model's risk map falls below this reward (riskmap.planner.risk_goal); "
                           "default: the route rule's goal",
    "demonstration": "which collision-free alternative demonstrates: safest (most room to every vehicle), "
                     "defensive (the same, never speeding up), lateral (the safest lane change where one is "
                     "clear) or mildest (least change from the attacked drive)",
    "keep": "which epoch of a round's fine-tune becomes its planner: last, or best by open-loop ADE on the "
            "natural validation windows (early stopping; default: %(default)s)",
    "replan_every": "k: the attack re-runs the planner every k iterations",
    "eval_scenes": "held-out attack scenes: every round's planner is attacked afresh on them",
    "eval_count": "held-out scenes attacked per round",
    "natural_env": "closed-loop natural traffic of this highway-env family (reactive), per round",
    "natural_episodes": "--natural-env episodes",
    "natural_seed": "--natural-env seed (and --natural-commonroad's)",
    "natural_commonroad": "held-out CommonRoad recordings for the closed-loop natural check, per round",
    "ade_windows": "open-loop ADE on this many of the original's validation windows",
    "traffic_model": "traffic CVAE (default: checkpoints/crash_traffic_<family>)",
    "selector_model": "selector directory (default: checkpoints/crash_selector_<family>)",
    "workers": "processes for attacks and evaluations",
    "batch_size": "scenes optimised together in an attack",
    "search_templates": "also search these scenario templates with NSGA-II each round and train on every "
                        "scenario that collided (default: CRASH's attacks only)",
    "search_pop": "evaluations per generation of a round's search",
    "search_gen": "generations of a round's search",
    "search_share": "cap on the search windows' share of a round's attack windows (search shards dropped "
                    "at random beyond it; default: no cap)",
}


def add_parsers(subparsers) -> None:
    from adversary.harden.loop import KEEP, HardenConfig
    from adversary.harden.windows import DEMONSTRATIONS
    from adversary.search.scenarios import TEMPLATES

    p = subparsers.add_parser("harden", help="fine-tune a risk-map planner on the CRASH attacks that beat it")
    add_config_options(p, HardenConfig, *(name for name in HELP if name not in ("natural_commonroad",
                                                                                "search_templates")),
                       help=HELP,
                       option_types={name: positive_int for name in ("rounds", "count", "epochs", "eval_count",
                                                                     "natural_episodes", "workers",
                                                                     "batch_size", "replan_every",
                                                                     "ade_windows", "search_pop", "search_gen")},
                       choices={"demonstration": DEMONSTRATIONS, "keep": KEEP})
    p.add_argument("--natural-commonroad", nargs="+", default=(), metavar="DIR_OR_FILE",
                   help=HELP["natural_commonroad"])
    p.add_argument("--search-templates", nargs="+", default=(), metavar="TEMPLATE", choices=sorted(TEMPLATES),
                   help=HELP["search_templates"])
    p.add_argument("--resume", action="store_true", help="go on from the last file written")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.set_defaults(func=_run_harden)

    p = subparsers.add_parser("harden-report", help="(re)write a hardening run's report page")
    p.add_argument("run", help="an `adversary harden --out` directory")
    p.set_defaults(func=_run_report)

