"""One parser for planner SPEC strings (DESIGN §2).

    idm              the IDM/MOBIL "human": the ego drives itself, no plan is made
    cv               constant velocity: current speed and heading for 6 s
    riskmap:PATH     the risk-map planner from a checkpoint (PATH with or without .safetensors)
    guard:SPEC       SPEC wrapped in the neuro-symbolic guard, TGAT-triggered (`guarded:` too)
    guard-always:SPEC  SPEC with the guard's deceleration plan always on at high speed
    replay           log playback of the human's recorded trajectory (needs a recorded episode)
    cnn:PATH, cnn_lstm:PATH (or cnn-lstm:PATH), rvsg:PATH
                     behaviour-cloning baselines from `riskmap train-baseline` checkpoints
"""

from __future__ import annotations

from rasterize.errors import InputError

SPECS = ("idm", "cv", "replay", "riskmap:PATH", "cnn:PATH", "cnn_lstm:PATH", "rvsg:PATH",
         "guard:SPEC", "guard-always:SPEC")


class HumanDriver:
    """Marker for `idm`: the simulator's IDM/MOBIL ego keeps driving itself."""

    name = "idm"


def make_planner(spec: str, seed: int = 0, goal_variance: float | None = None):
    """A `Planner` (or `HumanDriver`) for `spec`; `goal_variance` (cells²) overrides a risk-map
    checkpoint's planning-time goal variance."""
    kind, _, arg = spec.partition(":")
    if kind == "idm" and not arg:
        return HumanDriver()
    if kind == "cv" and not arg:
        from riskmap.baselines import ConstantVelocityPlanner

        return ConstantVelocityPlanner()
    if kind == "riskmap" and arg:
        from riskmap.planner import RiskMapPlanner

        return RiskMapPlanner.load(arg, seed=seed, goal_variance=goal_variance)
    if kind in ("guard", "guarded", "guard-always") and arg:
        from riskmap.guard.guarded import make_guarded

        return make_guarded("always" if kind == "guard-always" else "tgat", arg, seed=seed)
    if kind == "replay" and not arg:
        from riskmap.log_replay import ReplayPlanner

        return ReplayPlanner()
    if kind in ("cnn", "cnn_lstm", "cnn-lstm", "rvsg") and arg:
        from riskmap.bc import BCPlanner

        return BCPlanner.load(arg, expected_kind=kind)
    raise InputError(f"unknown planner spec {spec!r}; use one of {', '.join(SPECS)}")
