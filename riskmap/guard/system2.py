"""System 2: the BDI agent that runs the deceleration plans (`deceleration.asl`).

The plans are AgentSpeak, run by the `py-agentspeak` interpreter (imported lazily: it is an
optional dependency, GPL-3.0, installed with the `guard` extra). Each control step the
orchestrator replaces the perceived beliefs `alert`, `speed(V)`, `obstacle_ahead` and `ttc(T)`,
posts the goal `!control` and runs the agent until it is idle; the registered action
`.slow_down(Mode)` reports the plan's decision back to Python.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from rasterize.errors import InputError

PLANS_PATH = Path(__file__).with_name("deceleration.asl")


@dataclass(frozen=True)
class System2Config:
    speed_threshold_mps: float = 5.0   # "high speed": above this the plans may slow the ego down
    decel_mps2: float = 3.0            # a: the deceleration asked for by `.slow_down`
    control_hz: float = 2.0            # f: decisions per second (N = v0 / a · f frames)
    stop_speed_mps: float = 0.5        # a sustained deceleration ends below this speed
    short_ttc_s: float = 1.5           # a warning with a time to contact below this brakes hard


def _agentspeak():
    try:
        import agentspeak
        import agentspeak.runtime
        import agentspeak.stdlib
    except ImportError:
        raise InputError("the guard's System 2 needs the optional AgentSpeak interpreter (GPL-3.0); "
                         "install it with `pip install -e .[guard]`") from None
    return agentspeak


class DecelerationAgent:
    """One BDI agent per driven ego. `decide(...)` → None (no intervention), "single", "sustained"
    or "hard"."""

    def __init__(self, config: System2Config = System2Config(), plans: Path = PLANS_PATH):
        asp = _agentspeak()
        self.config = config
        self._asp = asp
        self._decision: str | None = None
        actions = asp.Actions(asp.stdlib.actions)

        @actions.add(".slow_down", 1)
        def _slow_down(agent, term, intention):
            self._decision = str(asp.grounded(term.args[0], intention.scope))
            yield

        env = asp.runtime.Environment()
        with open(plans) as source:
            self._agent = env.build_agent(source, actions)
        for name, value in (("speed_threshold", config.speed_threshold_mps), ("decel_rate", config.decel_mps2),
                            ("control_hz", config.control_hz), ("stop_speed", config.stop_speed_mps),
                            ("short_ttc", config.short_ttc_s)):
            self._tell(name, float(value))
        self._percepts: list = []

    def _belief(self, name: str, *args):
        return self._asp.Literal(name, tuple(args))

    def _tell(self, name: str, *args) -> None:
        asp = self._asp
        self._agent.call(asp.Trigger.addition, asp.GoalType.belief, self._belief(name, *args),
                         asp.runtime.Intention())

    def _untell(self, literal) -> None:
        asp = self._asp
        self._agent.call(asp.Trigger.removal, asp.GoalType.belief, literal, asp.runtime.Intention())

    def reset(self) -> None:
        """Forget the perceptions and any deceleration in progress (a new episode)."""
        for literal in self._percepts + list(self._agent.beliefs[("braking", 1)]):
            self._untell(literal)
        self._percepts = []
        self._agent.intentions.clear()

    def set_speed_threshold(self, speed_mps: float) -> None:
        """Replace the belief speed_threshold(T) (it differs between scenario families)."""
        for literal in list(self._agent.beliefs[("speed_threshold", 1)]):
            self._untell(literal)
        self._tell("speed_threshold", float(speed_mps))

    @property
    def braking_frames_left(self) -> float | None:
        """K of the belief braking(K), or None when no sustained deceleration is under way."""
        beliefs = self._agent.beliefs[("braking", 1)]
        return float(next(iter(beliefs)).args[0]) if beliefs else None

    def decide(self, alert: bool, speed_mps: float, obstacle_ahead: bool,
               ttc_s: float | None = None) -> str | None:
        """One frame: perceive, reason, act. `ttc_s`: the predictor's time to contact (None: unknown)."""
        asp = self._asp
        for literal in self._percepts:
            self._untell(literal)
        self._percepts = [self._belief("speed", float(speed_mps))]
        if alert:
            self._percepts.append(self._belief("alert"))
        if obstacle_ahead:
            self._percepts.append(self._belief("obstacle_ahead"))
        if ttc_s is not None:
            self._percepts.append(self._belief("ttc", float(ttc_s)))
        for literal in self._percepts:
            self._agent.call(asp.Trigger.addition, asp.GoalType.belief, literal, asp.runtime.Intention())
        self._decision = None
        self._agent.call(asp.Trigger.addition, asp.GoalType.achievement, self._belief("control"),
                         asp.runtime.Intention())
        self._agent.run()
        return self._decision
