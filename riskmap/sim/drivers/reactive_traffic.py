"""Reactive replay of a CommonRoad recording (`riskmap evaluate --commonroad --mode reactive`).

Every other recorded vehicle keeps its recorded path; its progress along it follows the log
unless the ego is in its way, when it brakes with IDM and falls behind the log, then catches up
(never ahead of it). The vehicles react only to the ego, not to each other, so an ego that drives
as the recorded human did leaves the recording unchanged (tested).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rasterize.commonroad.tracks import RecordedTraffic
from rasterize.geometry import Polyline, arc_lengths
from rasterize.scene import STATE_DIM
from riskmap.sim.drivers.idm import idm_acceleration, idm_desired_gap


@dataclass(frozen=True)
class IdmParams:
    """How a reactive vehicle follows the ego: the Intelligent Driver Model (Treiber, Hennecke and
    Helbing 2000), as nuPlan's and Waymax's reactive agents. Metres, seconds, m/s, m/s^2."""

    min_gap_m: float = 2.0               # s0: standstill gap
    headway_s: float = 1.0               # T: time gap
    max_accel_mps2: float = 1.5          # a
    comfort_decel_mps2: float = 2.0      # b
    max_decel_mps2: float = 6.0          # the hardest braking (IDM's is unbounded near contact)
    lateral_tolerance_m: float = 1.8     # about half a lane: the ego is in the way this close to the path
    lookahead_m: float = 100.0           # an ego farther ahead (bumper to bumper) is not followed
    min_desired_speed_mps: float = 0.1   # keeps the free-road term finite where the log stood still

    def desired_gap(self, speed: float, closing: float) -> float:
        """s* (m) at `speed` closing in on the ego at `closing` m/s (`riskmap.sim.drivers.idm`)."""
        return idm_desired_gap(speed, closing, min_gap_m=self.min_gap_m, headway_s=self.headway_s,
                               max_accel_mps2=self.max_accel_mps2, comfort_decel_mps2=self.comfort_decel_mps2)

    def accel(self, speed: float, desired_speed: float, gap: float | None = None,
              desired_gap: float = 0.0) -> float:
        """IDM acceleration (`riskmap.sim.drivers.idm`, exponent 4): free road towards `desired_speed`
        (at least `min_desired_speed_mps`), plus the ego term with s* = `desired_gap` when `gap`
        is set."""
        return idm_acceleration(speed, max(desired_speed, self.min_desired_speed_mps),
                                max_accel_mps2=self.max_accel_mps2, max_decel_mps2=self.max_decel_mps2,
                                delta=4, gap_m=gap, desired_gap_m=desired_gap)


class _RecordedPath:
    """One vehicle's recorded positions as a polyline, and arc length <-> recorded time on it.

    Positions between recorded steps are linear in time (as `RecordedTraffic.resample`), so the
    arc length is too, and resampling at `time_at(arc)` puts the vehicle at that arc length."""

    def __init__(self, traffic: RecordedTraffic, agent: int):
        first, last = traffic.span(agent)
        self.xy = traffic.states[agent, first: last + 1, :2]
        self.speed = traffic.states[agent, first: last + 1, 4]
        self.t = np.arange(first, last + 1) * traffic.dt_s
        self.arc = arc_lengths(self.xy)
        self.line = Polyline(self.xy) if len(self.xy) >= 2 else None

    def present(self, time_s: float) -> bool:
        return self.t[0] - 1e-9 <= time_s <= self.t[-1] + 1e-9

    def arc_at(self, time_s: float) -> float:
        return float(np.interp(time_s, self.t, self.arc))

    def speed_at(self, time_s: float) -> float:
        return float(np.interp(time_s, self.t, self.speed))

    def time_at(self, arc_m: float) -> float:
        """The first recorded time at `arc_m` (the log may stand still there for a while)."""
        j = int(np.searchsorted(self.arc, arc_m, side="left"))
        if j == 0:
            return float(self.t[0])
        if j >= len(self.arc):
            return float(self.t[-1])
        frac = (arc_m - self.arc[j - 1]) / (self.arc[j] - self.arc[j - 1])
        return float(self.t[j - 1] + frac * (self.t[j] - self.t[j - 1]))

    def locate(self, xy: np.ndarray, tolerance_m: float) -> tuple[float, np.ndarray] | None:
        """Arc length and unit direction of the path nearest `xy`, if within `tolerance_m` of it."""
        if self.line is None:
            return None
        k, u, distance = self.line.nearest(xy)
        d = self.line.segments[k]
        if distance > tolerance_m or (d * d).sum() < 1e-12:
            return None
        return float(self.arc[k] + u * self.line.lengths[k]), d / self.line.lengths[k]


class ReactiveTraffic:
    """`reactive` mode: each other vehicle keeps its recorded path but owns its progress on it.

    A vehicle in step with its log stays so (exactly the recording) unless the ego is ahead of it
    on its path and closer, bumper to bumper, than IDM's desired gap s*, capped by the gap the
    recording had to the recorded human there (so an ego that drives as the human did changes
    nothing). Then it brakes (IDM) and falls behind its log; behind it, it drives IDM towards its
    recorded speed, never past where the log has it, and is in step again once it gets there.
    The others react to the ego only: to each other they stay as recorded.
    States are kept per world step (`states_at`), for the planner's history and the metrics.
    """

    def __init__(self, traffic: RecordedTraffic, others: np.ndarray, ego: int, start_s: float,
                 dt: float, idm: IdmParams = IdmParams()):
        self.traffic, self.others, self.ego, self.dt, self.idm = traffic, others, ego, dt, idm
        self.column = {int(a): i for i, a in enumerate(others)}
        self.paths: dict[int, _RecordedPath] = {}
        self.times = [start_s]
        # Per step: in step with the log (then at the world's time), else the log time whose
        # position it holds and its own speed.
        self.synced = [np.ones(len(others), dtype=bool)]
        self.log_time = [np.full(len(others), start_s)]
        self.speed = [np.zeros(len(others))]

    def _path(self, agent: int) -> _RecordedPath:
        if agent not in self.paths:
            self.paths[agent] = _RecordedPath(self.traffic, agent)
        return self.paths[agent]

    def _ego_ahead(self, agent: int, path: _RecordedPath, arc_m: float,
                   ego_state: np.ndarray) -> tuple[float, float] | None:
        """Bumper gap (m) to the ego and its speed along the path, if it is ahead on the path."""
        hit = path.locate(ego_state[:2], self.idm.lateral_tolerance_m)
        if hit is None or hit[0] <= arc_m:
            return None
        gap = hit[0] - arc_m - 0.5 * (self.traffic.sizes[agent, 0] + self.traffic.sizes[self.ego, 0])
        if gap > self.idm.lookahead_m:
            return None
        return gap, float(ego_state[4] * np.dot(ego_state[2:4], hit[1]))

    def step(self, ego_state: np.ndarray) -> None:
        """Advance every other vehicle one `dt` from the last step, reacting to `ego_state` then."""
        now_s = self.times[-1]
        next_s = now_s + self.dt
        synced, log_time, speed = (self.synced[-1].copy(), self.log_time[-1].copy(),
                                   self.speed[-1].copy())
        human, human_here = self.traffic.resample(np.array([self.ego]), np.array([now_s]))
        for i, agent in enumerate(self.others):
            path = self._path(int(agent))
            tau = now_s if synced[i] else log_time[i]
            if not path.present(tau):
                synced[i], log_time[i] = True, next_s
                continue
            moved = self._advance(int(agent), path, bool(synced[i]), tau, float(speed[i]), now_s,
                                  ego_state, human[0, 0] if human_here[0, 0] else None)
            if moved is None:
                synced[i], log_time[i] = True, next_s
            else:
                synced[i] = False
                log_time[i], speed[i] = moved
        self.times.append(next_s)
        self.synced.append(synced)
        self.log_time.append(log_time)
        self.speed.append(speed)

    def _advance(self, agent: int, path: _RecordedPath, synced: bool, tau: float, speed: float,
                 now_s: float, ego_state: np.ndarray, human: np.ndarray | None):
        """(log time, speed) of `agent` after one step, or None when it is (again) in step with
        its log."""
        arc = path.arc_at(tau)
        if synced:
            speed = path.speed_at(now_s)
        lead = self._ego_ahead(agent, path, arc, ego_state)
        desired = np.inf
        if lead is not None:
            recorded = None if human is None else self._ego_ahead(agent, path, arc, human)
            # Never want more room than the recording kept to the human here: a follower that
            # drove closer than s* to the human must not brake for an ego in the human's place.
            desired = min(self.idm.desired_gap(speed, speed - lead[1]),
                          np.inf if recorded is None else recorded[0])
        if synced and (lead is None or lead[0] >= desired - 1e-6):
            return None
        # Where the log stood still the recorded speed there is ~0: also aim for the log's speed
        # now, so a vehicle held back at such a place does not stay stuck there.
        target = max(path.speed_at(tau), path.speed_at(now_s))
        accel = self.idm.accel(speed, target, None if lead is None else lead[0], desired)
        new_speed = max(0.0, speed + accel * self.dt)      # braking never reverses
        new_arc = arc + new_speed * self.dt
        if new_arc >= path.arc_at(now_s + self.dt) - 1e-9:  # caught up: never ahead of the log
            return None
        return path.time_at(new_arc), new_speed

    def states_at(self, agents: np.ndarray, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """As `RecordedTraffic.resample`, at the world's steps (or before the first): where each
        vehicle was then, with its own speed while it was behind its log."""
        out = np.zeros((len(agents), len(times_s), STATE_DIM))
        valid = np.zeros((len(agents), len(times_s)), dtype=bool)
        steps = np.clip(np.round((times_s - self.times[0]) / self.dt).astype(np.int64), 0,
                        len(self.times) - 1)
        before = times_s < self.times[0] + 1e-9
        synced, log_time, speed = (np.asarray(self.synced), np.asarray(self.log_time),
                                   np.asarray(self.speed))
        for j, agent in enumerate(agents):
            i = self.column[int(agent)]
            behind = ~before & ~synced[steps, i]
            tau = np.where(behind, log_time[steps, i], times_s)
            states, present = self.traffic.resample(np.array([agent]), tau)
            states[0, behind, 4] = speed[steps[behind], i]
            out[j], valid[j] = states[0], present[0]
        return out, valid
