"""`Tracks`: every agent's recorded states over a whole rollout, as one value.

Shapes, stated once:
    A agents, S recorded steps.
    states  [A, S, 6]  (x, y, heading_x, heading_y, speed, yaw_rate): world metres, unit heading
                       vector, metres/second, radians/second (`rasterize.scene.STATE_DIM`).
    valid   [A, S]     bool, True where the agent is recorded at that step.
    sizes   [A, 2]     (length, width) in metres.
    kinds   [A]        int8 :class:`rasterize.scene.AgentKind` codes.
    ids     [A]        optional agent ids (e.g. the log agent each row replays, -1 none), else None.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.scene import STATE_DIM, AgentsOverSteps


@dataclass(frozen=True, eq=False)
class Tracks(AgentsOverSteps):
    """A recorded rollout (module docstring). Arrays are held as given, not copied."""

    states: np.ndarray      # [A, S, 6] (x, y, heading_x, heading_y, speed, yaw_rate)
    valid: np.ndarray       # [A, S] bool
    sizes: np.ndarray       # [A, 2] length, width in m
    kinds: np.ndarray       # [A] int8 AgentKind codes
    ids: np.ndarray | None = None   # [A] agent ids, or None

    def __post_init__(self):
        shape = np.shape(self.states)
        if len(shape) != 3 or shape[2] != STATE_DIM:
            raise ValueError(f"Tracks.states must have shape [A, S, {STATE_DIM}], got {shape}")
        a, s = shape[:2]
        for name, expected in (("valid", (a, s)), ("sizes", (a, 2)), ("kinds", (a,))):
            got = np.shape(getattr(self, name))
            if got != expected:
                raise ValueError(f"Tracks.{name} must have shape {list(expected)} ([A, ...] with "
                                 f"states {list(shape)}), got {list(got)}")
        if self.ids is not None and np.shape(self.ids) != (a,):
            raise ValueError(f"Tracks.ids must have shape [{a}] (A) or be None, "
                             f"got {list(np.shape(self.ids))}")

    @classmethod
    def of_scene(cls, scene) -> Tracks:
        """A `rasterize.scene.Scene`'s agents over its steps (ids: its `agent_ids`)."""
        return cls(scene.states, scene.valid, scene.sizes, scene.kinds, scene.agent_ids)


class ReadsTracks:
    """For holders whose `tracks` field keeps a rollout's arrays (a CRASH rollout, an attacked run):
    `holder.states`, `.valid`, `.sizes`, `.kinds` and `.log_ids` (the tracks' ids) read the tracks'
    own, so that the arrays are held once."""

    @property
    def states(self) -> np.ndarray:
        return self.tracks.states

    @property
    def valid(self) -> np.ndarray:
        return self.tracks.valid

    @property
    def sizes(self) -> np.ndarray:
        return self.tracks.sizes

    @property
    def kinds(self) -> np.ndarray:
        return self.tracks.kinds

    @property
    def log_ids(self) -> np.ndarray | None:
        return self.tracks.ids
