"""`riskmap guard collect|train|evaluate`: the guard's accident data and its TGAT predictor."""

from __future__ import annotations

import argparse
from pathlib import Path

from riskmap.infra.cli import positive_int


def cmd_collect(args: argparse.Namespace) -> int:
    from riskmap.guard.dataset import GuardCollectConfig, collect

    config = GuardCollectConfig(seen_envs=tuple(args.seen_envs.split(",")),
                                unseen_envs=tuple(args.unseen_envs.split(",")), train_episodes=args.train_episodes, seen_test_episodes=args.seen_episodes,
                                unseen_episodes=args.unseen_episodes, planner_every=args.planner_every,
                                seed=args.seed, episode_s=args.episode_s)
    manifest = collect(config, Path(args.out), resume=args.resume, progress=not args.quiet)
    for split, c in manifest["splits"].items():
        print(f"{split}: {c['windows']} windows ({c['positives']} positive) from {c['episodes']} episodes "
              f"({c['crashes']} crashes)")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    from riskmap.guard.train import GuardTrainConfig, train

    config = GuardTrainConfig(epochs=args.epochs, patience=args.patience, lr=args.lr,
                              batch_size=args.batch_size, seed=args.seed)
    result = train(Path(args.data), Path(args.out), config, resume=args.resume, progress=not args.quiet)
    for split in ("seen", "unseen"):
        m = result["test"][split]
        print(f"{split}: n={m['n']} ({m['positives']} positive) AP {m['ap']:.3f} AUC {m['auc']:.3f} "
              f"accuracy {m['accuracy']:.3f} F1 {m['f1']:.3f}")
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
    p = sub.add_parser("guard", help="the neuro-symbolic guard: accident data, TGAT training")
    guard_sub = p.add_subparsers(dest="guard_command", required=True)
    q = guard_sub.add_parser("collect", help="(ego, neighbour) accident windows from closed-loop episodes")
    q.add_argument("--out", required=True, help="dataset directory to create")
    q.add_argument("--seen-envs", default="highway-v0,merge-v0",
                   help="comma-separated scenario families for training and the seen test")
    q.add_argument("--unseen-envs", default="intersection-v0", help="comma-separated held-out families")
    q.add_argument("--train-episodes", type=positive_int, default=40,
                   help="episodes per seen family (train + validation)")
    q.add_argument("--seen-episodes", type=positive_int, default=12, help="seen-test episodes per family")
    q.add_argument("--unseen-episodes", type=positive_int, default=16, help="held-out family episodes")
    q.add_argument("--planner-every", type=positive_int, default=4,
                   help="every k-th episode is also driven by the risk-map planner")
    q.add_argument("--episode-s", type=float, default=20.0, help="simulated seconds per episode")
    q.add_argument("--seed", type=int, default=0)
    q.add_argument("--resume", action="store_true")
    q.add_argument("--quiet", action="store_true")
    q.set_defaults(func=cmd_collect)
    q = guard_sub.add_parser("train", help="train the TGAT accident predictor")
    q.add_argument("--data", required=True, help="directory from `riskmap guard collect`")
    q.add_argument("--out", required=True, help="run directory")
    q.add_argument("--epochs", type=positive_int, default=40)
    q.add_argument("--patience", type=positive_int, default=8, help="epochs without a better val AP")
    q.add_argument("--lr", type=float, default=4e-4)
    q.add_argument("--batch-size", type=positive_int, default=8)
    q.add_argument("--seed", type=int, default=0)
    q.add_argument("--resume", action="store_true")
    q.add_argument("--quiet", action="store_true")
    q.set_defaults(func=cmd_train)
    q = guard_sub.add_parser("evaluate", help="score a TGAT checkpoint on splits of a guard dataset")
    q.add_argument("--checkpoint", default="checkpoints/guard_tgat", help="checkpoint path without suffix")
    q.add_argument("--data", required=True, help="guard dataset directory")
    q.add_argument("--splits", default="seen,unseen", help="comma-separated split names")
    q.add_argument("--out", default=None, help="write the metrics to this JSON file")
    q.set_defaults(func=cmd_evaluate)
