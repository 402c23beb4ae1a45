"""`riskmap guard collect|train|evaluate`: the guard's accident data and its TGAT predictor."""

from __future__ import annotations

import argparse
from pathlib import Path

from riskmap.guard.config import GuardTrainConfig, TGATConfig
from riskmap.guard.dataset import GuardCollectConfig
from riskmap.infra.cli import (
    add_command_group,
    add_config_options,
    add_run_options,
    config_from_args,
    positive_int,
)


def cmd_collect(args: argparse.Namespace) -> int:
    from riskmap.guard.dataset import collect

    config = config_from_args(GuardCollectConfig, args)
    manifest = collect(config, Path(args.out), resume=args.resume, progress=not args.quiet)
    for split, c in manifest["splits"].items():
        print(f"{split}: {c['windows']} windows ({c['positives']} positive) from {c['episodes']} episodes "
              f"({c['crashes']} crashes)")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from riskmap.guard.train import train

    config = config_from_args(GuardTrainConfig, args, model=config_from_args(TGATConfig, args))
    result = train(Path(args.data), Path(args.out), config, resume=args.resume, progress=not args.quiet)
    for split in ("seen", "unseen"):
        m = result["test"][split]
        print(f"{split}: n={m['n']} ({m['positives']} positive) AP {m['ap']:.3f} AUC {m['auc']:.3f} "
              f"accuracy {m['accuracy']:.3f} F1 {m['f1']:.3f}")
    print(f"alert threshold {result['alert_threshold']:.3f} ({result['alert_threshold_source']}); "
          f"label horizon {result['horizon_s']:g} s")
    print(f"checkpoint {Path(args.out) / 'best.safetensors'}")
    return 0


def cmd_evaluate(args: argparse.Namespace) -> int:
    from riskmap.guard.evaluate import evaluate_checkpoint
    from riskmap.infra.atomic import write_json

    result = evaluate_checkpoint(Path(args.checkpoint), Path(args.data), args.splits.split(","))
    for split, m in result.items():
        ap = "–" if m["ap"] is None else f"{m['ap']:.3f}"
        auc = "–" if m["auc"] is None else f"{m['auc']:.3f}"
        print(f"{split}: n={m['n']} ({m['positives']} positive) AP {ap} AUC {auc} "
              f"accuracy {m['accuracy']:.3f} F1 {m['f1']:.3f}")
    if args.out:
        write_json(Path(args.out), {"checkpoint": args.checkpoint, "data": args.data, "splits": result})
    return 0


def add_parsers(sub) -> None:
    """The `guard` command group under the top-level `riskmap` parser."""
    guard_sub = add_command_group(sub, "guard", help="the neuro-symbolic guard: accident data, TGAT training",
                                  dest="guard_command")
    q = guard_sub.add_parser("collect", help="(ego, neighbour) accident windows from closed-loop episodes")
    q.add_argument("--out", required=True, help="dataset directory to create")
    add_config_options(
        q, GuardCollectConfig, "seen_envs", "unseen_envs", "train_episodes", "seen_test_episodes",
        "unseen_episodes", "planner_every", "episode_s", "seed",
        flags={"seen_test_episodes": "--seen-episodes"},
        help={"seen_envs": "comma-separated scenario families for training and the seen test",
              "unseen_envs": "comma-separated held-out families",
              "train_episodes": "episodes per seen family (train + validation)",
              "seen_test_episodes": "seen-test episodes per family",
              "unseen_episodes": "held-out family episodes",
              "planner_every": "every k-th episode is also driven by the risk-map planner",
              "episode_s": "simulated seconds per episode",
              "seed": "seed of the training and validation episodes; the seen test uses SEED + 1, "
                      "the held-out families SEED + 2"},
        option_types={name: positive_int for name in ("train_episodes", "seen_test_episodes",
                                                      "unseen_episodes", "planner_every")})
    add_run_options(q, cmd_collect,
                    resume="continue an interrupted collection in --out (finished jobs are kept)")
    q = guard_sub.add_parser("train", help="train the TGAT accident predictor")
    q.add_argument("--data", required=True, help="directory from `riskmap guard collect`")
    q.add_argument("--out", required=True, help="run directory")
    add_config_options(q, GuardTrainConfig, "epochs", "patience", "lr", "batch_size", "seed", "ttc_weight",
                       "alert_ratio",
                       help={"epochs": "most training epochs (fewer when --patience stops it early)",
                             "lr": "Adam's learning rate",
                             "batch_size": "windows per optimiser step",
                             "seed": "seeds the weights' initialisation and the shuffling",
                             "patience": "epochs without a better val AP",
                             "ttc_weight": "weight of the time-to-contact loss beside the BCE",
                             "alert_ratio": "share of validation decision frames that alert: sets the "
                                            "checkpoint's alert threshold"},
                       option_types={name: positive_int for name in ("epochs", "patience", "batch_size")})
    q.add_argument("--closest-approach", action="store_true",
                   help="also feed each event's constant-velocity closest approach (distance, time) to the network")
    add_config_options(q, TGATConfig, "horizon_s",
                       help={"horizon_s": "label horizon: a window is positive when the ego touches the "
                                          "neighbour within this many seconds of its last event (≤ 3)"})
    add_run_options(q, cmd_train, resume="continue an interrupted run in --out from its last finished epoch")
    q = guard_sub.add_parser("evaluate", help="score a TGAT checkpoint on splits of a guard dataset")
    q.add_argument("--checkpoint", default="checkpoints/guard_tgat", help="checkpoint path without suffix")
    q.add_argument("--data", required=True, help="guard dataset directory")
    q.add_argument("--splits", default="seen,unseen", help="comma-separated split names")
    q.add_argument("--out", default=None, help="write the metrics to this JSON file")
    q.set_defaults(func=cmd_evaluate)
