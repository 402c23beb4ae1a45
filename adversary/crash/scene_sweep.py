"""`adversary scenes`: one writer of attack scenes over sweeps of two kinds.

A sweep proposes scenes in a fixed order and says, for each, either the recorded scene or why it
cannot be one:

- `EnvSweep`: episodes first_episode, first_episode + 1, ... of a seeded highway-env family
  (an episode is skipped when the human crashed before t0 + horizon, or no vehicle is near the
  ego); never runs out.
- `RecordingSweep`: the vehicles of CommonRoad recordings (`adversary.crash.recorded`): one file
  per moment of traffic (`sweep_files`), egos by obstacle id, each attacked `t0_s` after its first
  recorded time. Scene `episode` is the ego's place in that order (scene_seed 0), so no two scenes
  of a sweep share (scene_seed, episode); it runs out after the last vehicle.

`record_scenes` is the one writer: DIR/scene_NNNNN.npz (+ .json) and DIR/index.json, which lists
the scenes in order and every skipped candidate with why. The index is the commit point: a scene
counts once the index lists it, and `--resume` goes on from the sweep position the index holds
(`next_episode` / `next_candidate`, as written before the sweeps were one writer). A run killed
before its first index write left scene files but no index; resuming it starts afresh over them.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple, Protocol

from rasterize.errors import InputError
from rasterize.timebase import CONTROL_HZ
from riskmap.infra.atomic import write_json
from riskmap.infra.formats import Format
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import lock_out_dir, read_settings, refuse_unless_resume

INDEX = "index.json"


class Candidate(NamedTuple):
    """One place in a sweep: its number (the scene's episode), where it is (for progress lines),
    and the recorded scene or, when it cannot be one, the index's "skipped" entry."""

    number: int
    where: str
    record: object | None          # adversary.crash.scenes.SceneRecord
    skipped: dict | None


class SceneSweep(Protocol):
    position_key: str              # the index's resume position ("next_episode", "next_candidate")

    def check(self) -> None:
        """InputError for settings no scene can satisfy, before --out exists (inside the sweep they
        would only skip one candidate after another)."""

    def new_index(self) -> dict:
        """The index of a fresh run: its settings, no scenes, the sweep's first position."""

    def refusal(self, index: dict) -> str | None:
        """Why an existing index cannot be resumed with these settings (None: it can)."""

    def candidates(self, start: int) -> Iterator[Candidate]:
        """The sweep from position `start` on, tried lazily: a candidate is recorded only when asked for."""

    def update(self, index: dict) -> None:
        """What the index learns once the sweep is known (the number of candidates), if anything."""


@dataclass(frozen=True)
class EnvSweep:
    """Episodes of a seeded highway-env family; `static_agents` parked / stopped vehicles added to
    every episode (`riskmap.sim.drivers.static_agents`), kept in each scene and in the index."""

    env_id: str
    seed: int
    first_episode: int = 0
    t0_s: float = 2.0
    static_agents: int = 0
    position_key = "next_episode"

    def _scene(self, episode: int):
        from adversary.crash.scenes import AttackScene

        return AttackScene(self.env_id, self.seed, episode, self.t0_s, static_agents=self.static_agents)

    def check(self) -> None:
        if self.seed < 0 or self.first_episode < 0:
            raise InputError(f"--seed {self.seed} and --first-episode {self.first_episode} must be 0 or more")
        self._scene(self.first_episode).check(control_hz=CONTROL_HZ)

    def new_index(self) -> dict:
        return {"env_id": self.env_id, "seed": self.seed, "t0_s": self.t0_s, "static_agents": self.static_agents,
                "scenes": [], "skipped": [], "next_episode": self.first_episode, **provenance()}

    def refusal(self, index: dict) -> str | None:
        if (index["env_id"], index["seed"], index["t0_s"]) != (self.env_id, self.seed, self.t0_s):
            return f"holds scenes of {index['env_id']} seed {index['seed']}; choose another --out"
        if index["static_agents"] != self.static_agents:
            return (f"holds scenes with --static-agents {index['static_agents']}, not {self.static_agents}; "
                    "resume with the same --static-agents or choose another --out")
        return None

    def candidates(self, start: int) -> Iterator[Candidate]:
        from adversary.crash.scenes import record_attack_scene

        episode = start
        while True:
            try:
                yield Candidate(episode, f"episode {episode}", record_attack_scene(self._scene(episode)), None)
            except InputError as error:
                yield Candidate(episode, f"episode {episode}", None, {"episode": episode, "why": str(error)})
            episode += 1

    def update(self, index: dict) -> None:
        pass


@dataclass(frozen=True)
class RecordingSweep:
    """The vehicles of CommonRoad recordings (`inputs`: files or directories); `family` the
    traffic-model family (default: from the file names)."""

    inputs: tuple[str, ...]
    t0_s: float = 2.0
    family: str | None = None
    position_key = "next_candidate"

    def __post_init__(self) -> None:
        object.__setattr__(self, "inputs", tuple(str(p) for p in self.inputs))

    def _files(self) -> tuple[list[Path], str, list[dict]]:
        from adversary.crash.recorded import sweep_files
        from riskmap.data.collect_commonroad import scenario_files

        if not hasattr(self, "_swept"):            # read the recordings once per sweep
            object.__setattr__(self, "_swept", sweep_files(scenario_files(list(self.inputs), flag="--commonroad"),
                                                           self.family))
        return self._swept

    def _todo(self) -> list:
        from adversary.crash.recorded import candidates

        if not hasattr(self, "_candidates"):
            object.__setattr__(self, "_candidates", candidates(self._files()[0], self.t0_s))
        return self._candidates

    def _settings(self) -> dict:
        from adversary.crash.recorded import SMOOTHING_S
        from adversary.crash.scenes import RECORDED_ENV

        files, family, dropped = self._files()
        return {"env_id": RECORDED_ENV, "family": family, "t0_s": self.t0_s, "smoothing_s": SMOOTHING_S,
                "commonroad": [str(p) for p in files], "files_left_out": dropped}

    def check(self) -> None:
        from adversary.crash.scenes import RECORDED_ENV, AttackScene

        AttackScene(RECORDED_ENV, 0, 0, self.t0_s, recording="check", ego_id=0).check(control_hz=CONTROL_HZ)
        self._files()                              # unreadable or mixed recordings: refused here

    def new_index(self) -> dict:
        return {**self._settings(), "seed": 0, "scenes": [], "skipped": [], "next_candidate": 0, **provenance()}

    def refusal(self, index: dict) -> str | None:
        settings = self._settings()
        if {k: index.get(k) for k in settings} != settings:
            return "holds scenes of other recordings or settings; choose another --out"
        return None

    def candidates(self, start: int) -> Iterator[Candidate]:
        from adversary.crash.recorded import sweep_scenes

        files, family, _ = self._files()
        for number, path, ego_id, _, record, why in sweep_scenes(files, family, self.t0_s, start, self._todo()):
            yield Candidate(number, f"{path.name} vehicle {ego_id}", None if why else record,
                            {"file": path.name, "ego_id": ego_id, "why": why} if why else None)

    def update(self, index: dict) -> None:
        index["candidates"] = len(self._todo())


def _index_v1(index: dict) -> dict:
    """A scene index from before versions were kept: a highway-env sweep's index from before
    static vehicles existed holds scenes without any."""
    return {"static_agents": 0, **index} if "env_id" in index else dict(index)


# A scene directory's index.json; its readers (`read_index`, a resumed `record_scenes`) upgrade it.
SCENE_INDEX_FORMAT = Format("scene index", (_index_v1,))


def read_index(scenes_dir: Path) -> dict:
    """The index.json of a scene directory in today's layout (`SCENE_INDEX_FORMAT`); InputError
    naming it when it is missing or damaged."""
    scenes_dir = Path(scenes_dir)
    try:
        index = json.loads((scenes_dir / INDEX).read_text())
        names = index["scenes"]
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise ValueError("scenes is not a list of names")
    except (OSError, ValueError, KeyError, TypeError):
        raise InputError(f"--scenes {scenes_dir} holds no readable scene index ({INDEX}); make one with "
                         "`adversary scenes`") from None
    return SCENE_INDEX_FORMAT.read(index, where=scenes_dir / INDEX)


def record_scenes(sweep: SceneSweep, count: int, out: Path, resume: bool = False, progress: bool = True) -> dict:
    """Record `count` scenes of `sweep` into `out` (or go on with --resume); returns the index."""
    from adversary.crash.scenes import save_record

    out = Path(out)
    index_path = out / INDEX
    sweep.check()
    refuse_unless_resume(out, "scenes", None, resume)
    index = (SCENE_INDEX_FORMAT.read(read_settings(index_path), where=index_path)
             if resume and index_path.exists() else None)
    why = None if index is None else sweep.refusal(index)
    if why:
        raise InputError(f"--out {out} {why}")
    lock_out_dir(out)   # one writer (creates it); removes the temporary files a killed writer left
    index = SCENE_INDEX_FORMAT.stamp(sweep.new_index()) if index is None else index
    sweep.update(index)
    found = sweep.candidates(index[sweep.position_key])
    while len(index["scenes"]) < count:         # ask for the next candidate only while one is wanted
        candidate = next(found, None)
        if candidate is None:
            break
        if candidate.record is None:
            index["skipped"].append(candidate.skipped)
        else:
            name = f"scene_{candidate.number:05d}"
            save_record(candidate.record, out / f"{name}.npz")
            index["scenes"].append(name)
            if progress and len(index["scenes"]) % 10 == 0:
                print(f"{len(index['scenes'])}/{count} scenes ({candidate.where})", flush=True)
        index[sweep.position_key] = candidate.number + 1
        write_json(index_path, index)
    write_json(index_path, index)
    return index


__all__ = ["Candidate", "EnvSweep", "RecordingSweep", "SceneSweep", "read_index", "record_scenes"]
