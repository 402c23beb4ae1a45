"""The toolkit's one time base: control rate, replanning rate, history, plan horizon and step.

Every package states its rates and windows from here (it lives in `rasterize`, the lowest layer,
so `riskmap` and `adversary` can import it too):

- CONTROL_HZ = 10: highway-env is simulated, and recordings are logged and replayed, at 10 Hz;
  the tracking controller acts at every such step.
- REPLAN_HZ = 2: a planner makes a new plan every 0.5 s (every 5th control step).
- HISTORY_S = 2.0: the raster and every training window show 2 s of past (4 steps at 2 Hz
  before the current one).
- A plan is PLAN_STEPS = 12 waypoints PLAN_DT_S = 0.5 s apart, FUTURE_S = 6 s ahead; a training
  window's future is the same 12 steps at 2 Hz, so that it is what a plan is learnt from.

Configs keep their own fields (`control_hz`, `replan_hz`, `history_s`, `future_s`, ...) with
these values as defaults, so saved configs are unchanged; this module only says what the
defaults are.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class TimeBase:
    control_hz: int = 10          # simulation, recording and control steps per second (Hz)
    replan_hz: int = 2            # plans per second (Hz); divides control_hz
    history_s: float = 2.0        # seconds of past a scene / raster / window shows
    future_s: float = 6.0         # seconds a plan (and a window's future) covers
    plan_dt_s: float = 0.5        # seconds between plan waypoints (and window steps, 2 Hz)

    @property
    def plan_steps(self) -> int:
        """Waypoints in a plan (12): future_s / plan_dt_s."""
        return round(self.future_s / self.plan_dt_s)


TIME_BASE = TimeBase()

CONTROL_HZ: int = TIME_BASE.control_hz
REPLAN_HZ: int = TIME_BASE.replan_hz
HISTORY_S: float = TIME_BASE.history_s
FUTURE_S: float = TIME_BASE.future_s
PLAN_DT_S: float = TIME_BASE.plan_dt_s
PLAN_STEPS: int = TIME_BASE.plan_steps

__all__ = ["CONTROL_HZ", "FUTURE_S", "HISTORY_S", "PLAN_DT_S", "PLAN_STEPS", "REPLAN_HZ", "TIME_BASE",
           "TimeBase"]
