"""The CRASH subcommands: `adversary train-traffic` (the traffic CVAE), `train-selector` (ASM),
`scenes` (record held-out attack scenes), `attack` (select, generate, judge) and `evaluate` (the
planner benchmark on the stored scenes, unattacked)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from adversary.crash.config import TrainSelectorConfig, TrainTrafficConfig
from rasterize.timebase import REPLAN_HZ
from riskmap.registry import SPEC_HELP, display_name
from riskmap.infra.cli import (
    add_config_options,
    add_run_options,
    comma_list,
    config_from_args,
    non_negative_int,
    positive_float,
    positive_int,
)


def _run_train_traffic(args: argparse.Namespace) -> int:
    import torch

    from adversary.crash.train_traffic import train_traffic

    if args.threads:
        torch.set_num_threads(args.threads)
    config = config_from_args(TrainTrafficConfig, args)
    summary = train_traffic([Path(d) for d in args.data], Path(args.out), config, resume=args.resume,
                            progress=not args.quiet)
    print(json.dumps(summary["val"], indent=1))
    print(f"best checkpoint: {Path(args.out) / 'best.safetensors'}")
    return 0


def add_parsers(subparsers) -> None:
    add_attack_parsers(subparsers)
    p = subparsers.add_parser("train-traffic", help="train the traffic CVAE on collected windows")
    p.add_argument("--data", action="append", required=True,
                   help="a dataset from `riskmap collect` (repeat for several)")
    p.add_argument("--out", required=True, help="run directory (best.safetensors, log.jsonl, summary.json)")
    add_config_options(p, TrainTrafficConfig, "epochs", "batch_size", "lr", "kl_weight", "free_bits",
                       "max_windows_per_episode", "seed", "prior_collision_weight", "prior_off_road_weight",
                       help={"epochs": "passes over the training windows",
                             "batch_size": "windows per optimiser step",
                             "lr": "Adam's learning rate",
                             "kl_weight": "beta: weight of the KL term (beyond --free-bits) beside the "
                                          "reconstruction loss",
                             "seed": "seeds the weights' initialisation, the validation split and the "
                                     "shuffling",
                             "free_bits": "nats of KL per agent left unpenalised",
                             "max_windows_per_episode": "use at most this many windows of each episode "
                                                        "(0: all)",
                             "prior_collision_weight": "weight of the disc overlap (m, summed over steps and "
                                                       "pairs, per agent) of one prior sample per scene; "
                                                       "pairs that overlap in the log are left out (0: off)",
                             "prior_off_road_weight": "weight of the prior sample's box-corner distance to "
                                                      "the road (m, summed over corners and steps, per "
                                                      "agent; agents off-road in the log left out; 0: off)"},
                       option_types={"epochs": positive_int, "batch_size": positive_int})
    p.add_argument("--threads", type=int, default=0, help="torch CPU threads (0: as many as torch picks)")
    add_run_options(p, _run_train_traffic,
                    resume="continue an interrupted run in --out from its last finished epoch")


def _run_train_selector(args: argparse.Namespace) -> int:
    import torch

    from adversary.crash.train_selector import train_selector

    torch.set_num_threads(args.threads or 1)
    config = config_from_args(TrainSelectorConfig, args)
    summary = train_selector(Path(args.traffic_model), [Path(d) for d in args.data], Path(args.out), config,
                             resume=args.resume, progress=not args.quiet)
    print(json.dumps({k: summary[k] for k in ("selector_mam", "selector_no_mam", "val_baselines")}, indent=1))
    return 0


def _run_scenes(args: argparse.Namespace) -> int:
    from adversary.crash.scene_sweep import EnvSweep, RecordingSweep, record_scenes
    from rasterize.errors import InputError

    if args.commonroad:
        if args.seed is not None or args.first_episode != 0:
            raise InputError("--seed and --first-episode choose highway-env episodes; drop them with --commonroad")
        if args.static_agents:
            raise InputError("--static-agents adds vehicles to simulated episodes; drop it with --commonroad")
        index = record_scenes(RecordingSweep(tuple(args.commonroad), args.t0, args.family), args.count,
                              Path(args.out), resume=args.resume, progress=not args.quiet)
        print(f"{len(index['scenes'])} scenes in {args.out} ({len(index['skipped'])} vehicles skipped, "
              f"{len(index['files_left_out'])} files of the same traffic left out)")
        if len(index["scenes"]) < args.count:
            print(f"all {index['candidates']} vehicles of the recordings were tried; pass more recordings "
                  "for more scenes")
        return 0
    if args.seed is None or args.family is not None:
        raise InputError("--env needs --seed N (and takes no --family); pass --seed")
    index = record_scenes(EnvSweep(args.env, args.seed, args.first_episode, args.t0, args.static_agents),
                          args.count, Path(args.out), resume=args.resume, progress=not args.quiet)
    print(f"{len(index['scenes'])} scenes in {args.out} ({len(index['skipped'])} episodes skipped)")
    return 0


def default_models(scenes: Path, traffic: str | None, selectors: str | None) -> tuple[Path, Path]:
    """The given model paths, else the shipped ones of the scenes' family."""
    from adversary.crash.run import scenes_family

    if traffic is None or selectors is None:
        family = scenes_family(scenes)
        traffic = traffic or f"checkpoints/crash_traffic_{family}"
        selectors = selectors or f"checkpoints/crash_selector_{family}"
    return Path(traffic), Path(selectors)


def _run_attack(args: argparse.Namespace) -> int:
    from adversary.crash.attack import AttackConfig
    from adversary.crash.run import TABLE_HEADER, implausible_line, run_attacks, table_row

    config = AttackConfig(selector=args.selector, replan_every=args.replan_every,
                          iterations_replay=args.iterations or 300,
                          iterations_closed_loop=args.iterations or 200,
                          stop_on_collision=not args.full_iterations, lr=args.lr or AttackConfig.lr,
                          time_weighting=args.time_weighting, replan_hz=args.replan_hz,
                          validity_terms=not args.paper_loss)
    needs_selector = args.selector in ("crash", "crash-no-mam")
    traffic, selectors = default_models(Path(args.scenes), args.traffic_model, args.selector_model)
    summary = run_attacks(args.planner, Path(args.scenes), args.count, config, args.seed, Path(args.out),
                          traffic, selectors if needs_selector else None,
                          workers=args.workers, resume=args.resume, panels=args.panels,
                          progress=not args.quiet, batch_size=args.batch_size)
    label = f"{display_name(args.planner)} / {args.selector}"
    print(TABLE_HEADER)
    print(table_row(label, summary["summary"]))
    print(implausible_line(label, summary["summary"]), end="")
    return 0


def _run_evaluate(args: argparse.Namespace) -> int:
    from adversary.crash.evaluate_source import AttackSceneSource
    from rasterize.errors import InputError
    from riskmap.evaluation.evaluate import evaluate

    planners = comma_list(args.planners)
    if not planners:
        raise InputError(f"--planners {args.planners!r} names no planner; give comma-separated "
                         "SPECs, e.g. replay,idm,cv")
    source = AttackSceneSource(args.scenes, count=args.count, seed=args.seed)
    evaluate(source, planners, Path(args.out), workers=args.workers, resume=args.resume,
             progress=not args.quiet)
    print((Path(args.out) / "table.md").read_text(), end="")
    return 0


def add_attack_parsers(subparsers) -> None:
    from adversary.crash.config import SELECTOR_OBJECTIVES
    from adversary.crash.generate import TIME_WEIGHTINGS
    from adversary.crash.selection import SELECTORS

    p = subparsers.add_parser("train-selector", help="train CRASH's adversarial-agent selection module")
    p.add_argument("--traffic-model", required=True, help="checkpoint from `adversary train-traffic`")
    p.add_argument("--data", action="append", required=True, help="training dataset (repeatable)")
    p.add_argument("--out", required=True,
                   help="run directory (selector_mam, selector_no_mam, labels.jsonl, summary.json)")
    add_config_options(p, TrainSelectorConfig, "label_iterations", "max_scenes", "windows_per_episode",
                       "epochs", "seed", "objective", "unroll_steps", "unroll_lr", "lr",
                       help={"label_iterations": "iterations of the short attack that labels each "
                                                 "candidate (--objective labels)",
                             "max_scenes": "training scenes, drawn at random from the windows",
                             "windows_per_episode": "use at most this many windows of each episode",
                             "epochs": "passes over the training scenes, per selector",
                             "seed": "seeds the choice of scenes, the selectors' initialisation and "
                                     "the shuffling",
                             "lr": "Adam's learning rate for the selector",
                             "objective": "labels: fit p to each candidate's short-attack loss; unrolled: "
                                          "minimise the generation loss after --unroll-steps "
                                          "differentiable steps on the latents, with p in the loss",
                             "unroll_steps": "gradient steps on the latents unrolled (--objective unrolled)",
                             "unroll_lr": "their step size eta (--objective unrolled)"},
                       choices={"objective": SELECTOR_OBJECTIVES},
                       option_types={name: positive_int for name in ("label_iterations", "max_scenes",
                                                                     "windows_per_episode", "epochs",
                                                                     "unroll_steps")})
    p.add_argument("--threads", type=int, default=1, help="torch CPU threads (0 counts as 1)")
    add_run_options(p, _run_train_selector,
                    resume="continue an interrupted run in --out (labels and finished epochs are kept)")

    p = subparsers.add_parser("scenes", help="record held-out attack scenes from highway-env episodes "
                                             "or CommonRoad recordings")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--env", help="highway-v0 or intersection-v0")
    source.add_argument("--commonroad", nargs="+", metavar="DIR_OR_FILE",
                        help="CommonRoad recordings (.xml files or directories): their vehicles are the egos")
    p.add_argument("--family", default=None,
                   help="--commonroad: traffic-model family (default: from the file names, USA_US101* -> us101, "
                        "USA_Lanker* -> lankershim)")
    p.add_argument("--seed", type=int, default=None, help="--env: the episodes' seed (required)")
    p.add_argument("--count", type=positive_int, required=True, help="scenes to record")
    p.add_argument("--out", required=True,
                   help="scene directory (scene_NNNNN.npz + .json, index.json)")
    p.add_argument("--first-episode", type=int, default=0,
                   help="--env: the episode the sweep starts at")
    p.add_argument("--t0", type=float, default=2.0,
                   help="attack time in the episode (s); --commonroad: after each vehicle's first recorded time")
    p.add_argument("--static-agents", type=non_negative_int, default=0,
                   help="--env: parked/stopped vehicles added to each simulated episode (CRASH's "
                        "Motion-Aware Masking benchmark; 0 to 10)")
    add_run_options(p, _run_scenes,
                    resume="record more scenes into --out (the scenes its index lists are kept)")

    p = subparsers.add_parser("attack", help="CRASH / distance-based attacks on recorded scenes")
    p.add_argument("--planner", required=True, help="the ego under test, a " + SPEC_HELP)
    p.add_argument("--scenes", required=True, help="a directory from `adversary scenes`")
    p.add_argument("--count", type=positive_int, required=True,
                   help="attack the first N scenes of --scenes")
    p.add_argument("--selector", choices=SELECTORS, default="crash",
                   help="who becomes the adversary: crash (CRASH's selection module with Motion-Aware "
                        "Masking), crash-no-mam (without it), distance (STRIVE's), distance+mam, "
                        "nearest or random")
    p.add_argument("--seed", type=int, default=0,
                   help="seeds the planner and every scene's random draws (with the scene)")
    p.add_argument("--out", required=True,
                   help="run directory (OUT/attacks/<scene>.json, OUT/summary.json, OUT/table.md)")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="processes attacking batches of scenes (the results do not depend on it)")
    p.add_argument("--batch-size", type=positive_int, default=8, help="scenes optimised together")
    p.add_argument("--traffic-model", default=None,
                   help="traffic CVAE checkpoint (default: checkpoints/crash_traffic_<family>)")
    p.add_argument("--selector-model", default=None,
                   help="directory with selector_mam / selector_no_mam (default: checkpoints/crash_selector_<family>)")
    p.add_argument("--replan-every", type=positive_int, default=20, help="k: planner re-runs every k iterations")
    p.add_argument("--replan-hz", type=positive_int, default=REPLAN_HZ,
                   help="how often the ego under test replans in its drives (Hz; 1, 2, 5 or 10; default 2)")
    p.add_argument("--iterations", type=non_negative_int, default=0,
                   help="0: 300 for replay, 200 for a closed-loop planner")
    p.add_argument("--full-iterations", action="store_true", help="do not stop at the first collision")
    p.add_argument("--lr", type=positive_float, default=None, help="Adam's step on the latents (default 0.15)")
    p.add_argument("--time-weighting", choices=TIME_WEIGHTINGS, default="sum",
                   help="sum: CRASH's adversarial loss over every future step; softmin: weighted "
                        "towards the step of closest approach")
    p.add_argument("--paper-loss", action="store_true",
                   help="generate with CRASH's eq. 8 alone, without the validity terms (the adversary's "
                        "collisions with other agents and its kinematic excess; on by default)")
    p.add_argument("--panels", type=non_negative_int, default=0, help="write PNG panels of the first N scenes")
    add_run_options(p, _run_attack,
                    resume="continue an interrupted run in --out (the scenes already attacked are kept)")

    p = subparsers.add_parser("evaluate", help="closed-loop benchmark of planners (riskmap evaluate's "
                                               "Table I metrics) on stored attack scenes, driven without "
                                               "an attack")
    p.add_argument("--scenes", required=True,
                   help="a directory from `adversary scenes`: its scenes, in index order, are the episodes")
    p.add_argument("--planners", required=True, help="comma-separated; each a " + SPEC_HELP)
    p.add_argument("--out", required=True,
                   help="run directory (OUT/table.md, OUT/results.json, OUT/episodes.csv, per-episode "
                        "records OUT/episodes/<planner>/<scene>.json)")
    p.add_argument("--count", type=positive_int, default=None,
                   help="evaluate the first N scenes of --scenes (default: every one)")
    p.add_argument("--seed", type=int, default=0, help="seed of the planners")
    p.add_argument("--workers", type=positive_int, default=1,
                   help="processes driving episodes (the results do not depend on it)")
    add_run_options(p, _run_evaluate,
                    resume="continue an interrupted evaluation in --out (finished episodes are kept; it "
                           "may name more planners or a larger --count)")


