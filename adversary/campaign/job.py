"""One stress-test job: (planner SPEC, env id, scene, attack + params) -> one result record.

`run_job` is the only function the execution backends call; it is a plain top-level function of
picklable arguments, so a process pool and Ray run exactly the same code. Results depend only on
the job (fresh episode from its seed, planner state reset per episode), never on which worker or
in which order jobs run, so a resumed or distributed campaign gives the same numbers.

The attack's entry runs against the job's scene, whatever its kind (adversary.attacks.job_source):
an attack with episode hooks drives the job's scene with them; the others run the whole job
themselves (search attacks: a seeded scenario search, then the replay of its most critical
scenario; `crash`: CRASH on the job's recorded scene). A job of a recorded scenario family
carries its scene (`scene`: a RecordedScene, env id `commonroad:<family>`).
"""

from __future__ import annotations

import hashlib
import json
import re
import time
import traceback
from dataclasses import dataclass

from adversary.attacks.job_source import run_entry
from adversary.attacks.monitor import SafetyConfig
from adversary.attacks.recorded import RecordedScene
from adversary.attacks.registry import attack_entry
from rasterize.timebase import CONTROL_HZ, REPLAN_HZ
from riskmap.infra.config_mapping import to_plain


@dataclass(frozen=True)
class Budget:
    episode_s: float | None = None    # simulated seconds per episode; None: the family's default
    control_hz: int = CONTROL_HZ      # simulation and control rate
    replan_hz: int = REPLAN_HZ


@dataclass(frozen=True)
class Job:
    planner: str              # SPEC (riskmap.registry)
    env_id: str
    scene_seed: int           # the scene is episode `episode` of `riskmap drive --seed scene_seed`
    episode: int
    attack: str               # the attack's label in the campaign
    attack_name: str          # its registered name
    attack_params: object     # its frozen params dataclass
    planner_seed: int
    budget: Budget
    safety: SafetyConfig
    scene: RecordedScene | None = None    # a recorded family's scene (env_id commonroad:<family>)

    @property
    def job_id(self) -> str:
        """Readable and unique: the key fields, then a hash of every field. A highway-env job's
        hash leaves out the (empty) scene, so ids from before recorded families stay; a recorded
        scene enters by its recording's file name, so moving the recordings keeps the ids. The
        planner enters by its whole SPEC, not its display name: the id is the key `--resume`
        finds a finished job by (records/JOB_ID.json), and a display name depends on the other
        planners listed (`-2` suffixes), so campaigns keep resuming as they did."""
        plain = to_plain(self)
        if self.scene is None:
            del plain["scene"]
        else:
            plain["scene"]["recording"] = self.scene.describe()["recording"]
        digest = hashlib.sha1(json.dumps(plain, sort_keys=True).encode()).hexdigest()[:10]
        slug = re.sub(r"[^A-Za-z0-9]+", "-", f"{self.planner}_{self.env_id}_s{self.scene_seed}"
                      f"e{self.episode}_{self.attack}").strip("-")
        return f"{slug[-80:]}-{digest}"

    def describe(self) -> dict:
        entry = attack_entry(self.attack_name)
        return {"job_id": self.job_id, "planner": self.planner, "env_id": self.env_id,
                "scene_seed": self.scene_seed, "episode": self.episode, "attack": self.attack,
                "attack_name": self.attack_name, "attack_category": entry.category,
                "attack_params": to_plain(self.attack_params),
                **({} if self.scene is None else self.scene.describe())}


def error_result(job: Job, error: BaseException, trace: str = "") -> dict:
    """The result of a job that failed: its record carries the error's first line."""
    record = {**job.describe(), "status": "error",
              "error": (f"{type(error).__name__}: {error}".splitlines() or [""])[0][:500],
              "traceback": trace[-2000:], "timing": {}}
    return {"record": record, "artifact": None}


def run_job(job: Job) -> dict:
    """{"record": dict, "artifact": npz bytes or None}; a failure is a record, never a raise."""
    started = time.perf_counter()
    try:
        import torch

        torch.set_num_threads(1)
        record, artifact = run_entry(attack_entry(job.attack_name), job)
        result = {"record": {**job.describe(), "status": "ok", "error": None, **record},
                  "artifact": artifact}
    except Exception as error:  # noqa: BLE001  (a failing job is recorded and the campaign goes on)
        result = error_result(job, error, traceback.format_exc(limit=4))
    result["record"]["timing"]["wall_s"] = time.perf_counter() - started
    return result
