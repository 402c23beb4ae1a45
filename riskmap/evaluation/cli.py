"""`riskmap drive` (closed-loop episodes) and `riskmap evaluate` (the planner benchmark)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from rasterize.errors import InputError
from rasterize.timebase import REPLAN_HZ
from riskmap.infra.cli import add_run_options, comma_list, positive_float, positive_int
from riskmap.registry import SPEC_HELP


def _cmd_drive(args: argparse.Namespace) -> int:
    from riskmap.evaluation.drive import drive
    from riskmap.sim.worlds.highway_drive import DriveConfig

    if bool(args.checkpoint) == bool(args.planner):
        raise InputError("pass exactly one of --checkpoint CKPT or --planner SPEC")
    spec = args.planner or f"riskmap:{args.checkpoint}"
    config = DriveConfig(env_id=args.env, episodes=args.episodes, seed=args.seed)
    summary = drive(config, spec, Path(args.out), resume=args.resume, frames=args.frames,
                    progress=not args.quiet, goal_variance=args.goal_variance)["summary"]
    gap = "nobody near" if summary["min_gap_m"] is None else f"{summary['min_gap_m']:.1f} m"
    print(f"{spec} on {args.env}: {summary['episodes']} episodes, collision rate "
          f"{summary['collision_rate']:.2f}, distance {summary['distance_m']:.0f} m, "
          f"min gap {gap}, yielding events {summary['yield_events'] or 0:.2f} per episode "
          f"-> {Path(args.out) / 'summary.json'}")
    if summary["implausible_plans"]:
        print(f"{summary['implausible_plans']} implausible plans (driven as made), first "
              f"{summary['implausible_plan_first']}")
    return 0


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from riskmap.evaluation.evaluate import evaluate
    from riskmap.evaluation.sources import EnvSource, RecordingSource

    planners = tuple(p.strip() for p in args.planners.split(",") if p.strip())
    if not planners:
        raise InputError(f"--planners {args.planners!r} names no planner; give comma-separated "
                         "SPECs, e.g. idm,cv,riskmap:checkpoints/riskmap_highway")
    if args.commonroad:
        if args.env or args.episodes:
            raise InputError("--commonroad evaluates recorded vehicles: drop --env and --episodes "
                             "(--max-episodes N evaluates N of them)")
        source = RecordingSource(tuple(args.commonroad), seed=args.seed, goal=args.goal or "route",
                                 mode=args.mode, goal_variance=args.goal_variance,
                                 replan_hz=args.replan_hz, limit=args.max_episodes)
    else:
        if args.goal is not None or args.goal_variance is not None:
            raise InputError("--goal and --goal-variance are for recordings (--commonroad); on simulated "
                             "scenes the planner follows the route rule with its checkpoint's variance")
        if not args.env or not args.episodes:
            raise InputError("evaluate needs --env ENV and --episodes N (or --commonroad FILES)")
        source = EnvSource(env_id=args.env, episodes=args.episodes, seed=args.seed, mode=args.mode,
                           episode_s=args.episode_s, replan_hz=args.replan_hz)
    evaluate(source, planners, Path(args.out), workers=args.workers, resume=args.resume,
             progress=not args.quiet)
    print((Path(args.out) / "table.md").read_text(), end="")
    return 0


def _cmd_check_planner(args: argparse.Namespace) -> int:
    import numpy as np

    from riskmap.evaluation.check_planner import CheckConfig, check_planner
    from riskmap.registry import make_planner

    config = CheckConfig(envs=args.envs, episodes=args.episodes, episode_s=args.seconds,
                         seed=args.seed, recordings=tuple(args.commonroad or ()))
    planner = make_planner(args.spec, seed=args.seed)     # a bad SPEC: one line, before anything
    if config.recordings:
        print(f"checking {args.spec} on {config.episodes} recorded vehicle(s) of each recording "
              f"in {', '.join(config.recordings)}", flush=True)
    else:
        print(f"checking {args.spec} on {', '.join(config.envs)} ({config.episodes} episode(s) of "
              f"{config.episode_s:g} s each)", flush=True)
    findings = check_planner(args.spec, config, progress=not args.quiet, planner=planner)
    if findings.times_s:
        times = 1000 * np.asarray(findings.times_s)
        print(f"{findings.plans} plans; {np.median(times):.1f} ms median, {times.max():.1f} ms "
              "max per call (the loop replans every 500 ms)")
    if findings.no_solution:            # within the contract, but a user must see it
        print(f"{findings.no_solution} of {findings.plans + findings.no_solution} replans without a solution (the ego braked), "
              f"first {findings.no_solution_first}")
    for line in findings.lines():
        print(f"BROKEN: {line}")
    print(f"{args.spec}: {len(findings.counts)} contract problem(s)" if findings.counts
          else f"{args.spec}: keeps the planner contract on every scene tried")
    return 1 if findings.counts else 0


def _cmd_tune_goal_variance(args: argparse.Namespace) -> int:
    from riskmap.evaluation.open_loop import tune_goal_variance

    try:
        candidates = tuple(float(v) for v in args.candidates.split(","))
    except ValueError:
        raise InputError(f"--candidates {args.candidates!r}: give comma-separated numbers, e.g. 5,2,1") from None
    if not all(math.isfinite(v) and v > 0 for v in candidates):
        raise InputError(f"--candidates {args.candidates!r}: every goal variance must be a finite "
                         "number of cells² > 0, e.g. 5,2,1")
    planning = tune_goal_variance(Path(args.checkpoint), Path(args.data), candidates, args.limit,
                                  write=not args.dry_run, goal=args.goal, groups=args.groups,
                                  timing=args.timing,
                                  keep_gap=None if args.keep_gap is None else args.keep_gap == "on")
    key = "goal_variance" if args.goal == "route" else "human_goal_variance"
    print(f"chosen goal variance {planning[key]:g} (lowest mean ADE "
          f"{min(r['ade_m'] for r in planning['candidates' if args.goal == 'route' else 'human_candidates']):.2f} m)"
          + ("" if args.dry_run else f"; wrote planning.{key} to "
             f"{Path(args.checkpoint).with_suffix('.json')}"))
    return 0


def add_parsers(sub) -> None:
    p = sub.add_parser("drive", help="drive closed-loop episodes with a planner")
    p.add_argument("--checkpoint", help="risk-map planner checkpoint (same as --planner riskmap:CKPT)")
    p.add_argument("--planner", help=SPEC_HELP)
    p.add_argument("--env", required=True, help="highway-env id, e.g. highway-v0")
    p.add_argument("--episodes", type=positive_int, required=True, help="episodes to drive")
    p.add_argument("--seed", type=int, default=0,
                   help="episode i resets the env with a seed drawn from (SEED, i), the traffic "
                        "`riskmap collect` met with the same seed; also the planner's seed")
    p.add_argument("--out", required=True,
                   help="run directory (OUT/episodes/episode_NNNNNN.json, OUT/summary.json)")
    p.add_argument("--frames", action="store_true",
                   help="write a PNG per replan (OUT/frames): the scene and the plan")
    p.add_argument("--goal-variance", type=positive_float, default=None,
                   help="cells²; planning-time goal variance of a risk-map planner (default: the "
                        "checkpoint's)")
    add_run_options(p, _cmd_drive,
                    resume="continue an interrupted drive in --out (finished episodes are kept)")

    p = sub.add_parser("check-planner", help="drive a planner on a few scenes of each family and "
                       "say, one line each, where it breaks the planner contract")
    p.add_argument("spec", help=SPEC_HELP)
    p.add_argument("--envs", type=comma_list, default=("highway-v0", "merge-v0", "roundabout-v0",
                                                      "intersection-v0"),
                   help="comma-separated highway-env ids (default: one of each family)")
    p.add_argument("--commonroad", nargs="+", metavar="DIR_OR_FILE",
                   help="check on CommonRoad recordings instead of the highway-env families: "
                        "--episodes recorded vehicles of each file, driven as evaluate --commonroad "
                        "drives them (to the end of their record)")
    p.add_argument("--episodes", type=positive_int, default=1,
                   help="episodes per family (with --commonroad: recorded vehicles per file)")
    p.add_argument("--seconds", type=positive_float, default=8.0,
                   help="seconds driven per highway-env episode")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the planner and of the highway-env episodes (as drive --seed)")
    add_run_options(p, _cmd_check_planner)

    p = sub.add_parser("evaluate", help="closed-loop benchmark of planners (Table I metrics)")
    p.add_argument("--planners", required=True, help="comma-separated; each a " + SPEC_HELP)
    p.add_argument("--env", help="highway-env id (simulated scenes)")
    p.add_argument("--episodes", type=positive_int, help="episodes (simulated scenes)")
    p.add_argument("--max-episodes", type=positive_int, default=None,
                   help="with --commonroad: evaluate N of the recorded vehicles, drawn with --seed "
                        "(the same N for every planner; default: every one)")
    p.add_argument("--goal", choices=("route", "human"), default=None,
                   help="with --commonroad: the route rule's goal (default) or the recorded "
                        "vehicle's own end position (the planner paper's protocol)")
    p.add_argument("--goal-variance", type=positive_float, default=None,
                   help="with --commonroad: cells²; planning-time goal variance of risk-map planners "
                        "(default: the checkpoint's; see tune-goal-variance --goal)")
    p.add_argument("--commonroad", nargs="+", metavar="DIR_OR_FILE",
                   help="evaluate on recorded vehicles of CommonRoad files instead (--mode log or "
                        "reactive)")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the planners and of the simulated episodes (as drive --seed); with "
                        "--commonroad it draws the --max-episodes vehicles")
    p.add_argument("--mode", choices=("log", "reactive"), default="log",
                   help="log: other vehicles replay the human's record; reactive: IDM/MOBIL traffic "
                        "(with --commonroad: the recorded paths, braking for the ego)")
    p.add_argument("--episode-s", type=float, default=None,
                   help="simulated seconds per episode (default: the family's length)")
    p.add_argument("--replan-hz", type=positive_int, default=REPLAN_HZ,
                   help="how often planners replan (Hz; a divisor of the 10 Hz control rate; default 2)")
    p.add_argument("--out", required=True,
                   help="run directory (OUT/table.md, OUT/results.json, OUT/episodes.csv, per-episode "
                        "records)")
    p.add_argument("--workers", type=positive_int, default=1, help="processes (default 1)")
    add_run_options(p, _cmd_evaluate,
                    resume="continue an interrupted evaluation in --out (finished episodes are kept; it "
                           "may name more planners)")

    p = sub.add_parser("tune-goal-variance", help="choose a risk-map checkpoint's planning-time goal "
                                                   "variance on held-out windows (lowest ADE)")
    p.add_argument("--checkpoint", required=True, help="risk-map planner checkpoint")
    p.add_argument("--data", required=True, help="held-out windows (not training data)")
    p.add_argument("--candidates", default="5,2,1,0.5", help="goal variances, cells²")
    p.add_argument("--limit", type=positive_int, default=60, help="windows, evenly spread")
    p.add_argument("--goal", choices=("route", "human"), default="route",
                   help="plan towards the route rule's goal (planning.goal_variance, what riskmap:PATH "
                        "plans with) or the human's own end (planning.human_goal_variance, for "
                        "evaluate --commonroad --goal human --goal-variance)")
    p.add_argument("--groups", type=comma_list, default=None,
                   help="recorded data: only windows of these configurations (names or numbers), "
                        "e.g. the training ones, so the evaluation configurations stay unseen")
    p.add_argument("--timing", choices=("uniform", "kinematic"), default=None,
                   help="plan with this waypoint timing and record it in the sidecar (default: the "
                        "checkpoint's)")
    p.add_argument("--keep-gap", choices=("on", "off"), default=None,
                   help="plan with gap keeping behind vehicles on the path on or off, and record it "
                        "(default: the checkpoint's)")
    p.add_argument("--dry-run", action="store_true", help="print, do not write the sidecar")
    p.set_defaults(func=_cmd_tune_goal_variance)
