"""Campaign config: what to stress-test, read from YAML into frozen, validated dataclasses.

    name: tiny                        # shown in the report
    seed: 0                           # planner sampling seed; attacks derive theirs from it
    planners: [cv, idm, riskmap:checkpoints/riskmap_highway]   # SPECs (riskmap.registry)
    scenarios:                        # scenario families: episodes 0..N-1 of `riskmap drive --seed`
      - {env: highway-v0, seed: 0, episodes: 2}
      - {env: intersection-v0, seed: 0, episodes: 2, planners: [idm]}   # optional subset
      # or the first N scenes of a recorded sweep (`adversary scenes --commonroad`): CommonRoad
      # files, directories or globs relative to the working directory; optional family (default:
      # from the file names) and t0 (s after each vehicle's first recorded time)
      - {commonroad: [data/USA_US101-15_1_T-1.xml], episodes: 3, t0: 2.0}
    attacks:
      - {name: natural}
      - {name: aggressive_neighbour, label: aggr-nearest, params: {selection: nearest}}
      - {name: nsga2_search, envs: [highway-v0], params: {template: cut_in, pop: 6, generations: 3}}
      - {name: crash, label: MAM+ASM, params: {selector: crash, iterations: 60}}   # CRASH
    budget: {episode_s: 10, control_hz: 10, replan_hz: 2}
    safety: {close_gap_m: 2.0, ttc_s: 1.5, radius_m: 40, off_road_margin_m: 1.0}
    report: {gallery: 3}

Every job is (planner, scenario family episode, attack); `jobs()` lists them in a fixed order.
An attack with `envs` runs only on the families of those env ids (search attacks build their own
highway-v0 road, so they must be limited to highway-v0 families; adversary.attacks.search).
A recorded family's env id is `commonroad:<family>` (e.g. commonroad:us101; adversary.attacks.recorded);
only attacks that can run on recorded scenes (natural, crash) may apply to it. Reading a config
with recorded families parses their recordings and finds their scenes (a few seconds a file):
missing files, too few scenes or an attack that needs a highway-env world are refused here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import yaml

from adversary.attacks.base import RECORDED
from adversary.attacks.monitor import SafetyConfig
from adversary.attacks.recorded import (
    RecordedScene,
    recorded_env_id,
    recorded_family_of,
    recorded_files,
    recorded_sweep,
)
from adversary.attacks.registry import parse_attack_params
from adversary.campaign.job import Budget, Job
from rasterize.config import family_of_env
from rasterize.errors import InputError
from rasterize.timebase import HISTORY_S, PLAN_DT_S
from riskmap.infra.config_mapping import from_mapping, require, to_plain
from riskmap.registry import display_names

T0_STEP_S, T0_MIN_S = PLAN_DT_S, HISTORY_S   # a recorded scene's attack time: the window's grid and history
_ENV_ONLY, _RECORDED_ONLY = ("seed",), ("commonroad", "family", "t0")


@dataclass(frozen=True)
class ScenarioFamily:
    """Episodes of a highway-env seed (`env`) or the first scenes of a recorded sweep
    (`commonroad`); exactly one of the two."""

    env: str | None = None            # highway-env id
    commonroad: tuple[str, ...] = ()  # or CommonRoad recordings: files, directories, globs
    seed: int = 0                     # env: scene seed (riskmap drive --seed)
    episodes: int = 1                 # env: episodes 0..episodes-1 of that seed; commonroad: the
    #                                   sweep's first `episodes` scenes
    family: str | None = None         # commonroad: traffic-model family; None: from the file names
    t0: float = 2.0                   # commonroad: attack time, s after each ego's first record
    planners: tuple[str, ...] = ()    # empty: every planner of the campaign

    def __post_init__(self) -> None:
        require((self.env is None) != (not self.commonroad),
                "scenario family: give exactly one of env (a highway-env id) or commonroad (CommonRoad "
                "recordings: files, directories or globs)")
        if self.env is not None:
            family_of_env(self.env)   # an InputError naming the supported ids
        steps = self.t0 / T0_STEP_S
        require(self.t0 >= T0_MIN_S and abs(steps - round(steps)) < 1e-9,
                f"scenario {self.name}: t0 must be a multiple of {T0_STEP_S} s that is >= {T0_MIN_S}, "
                f"got {self.t0}")
        require(self.episodes >= 1, f"scenario {self.name}: episodes must be >= 1, got {self.episodes}")
        require(self.seed >= 0, f"scenario {self.name}: seed must be >= 0, got {self.seed}")

    @property
    def name(self) -> str:
        """The family in words (messages)."""
        return self.env or f"commonroad {', '.join(self.commonroad)}"

    def env_id(self, where: str = "scenario family") -> str:
        """The env id of its jobs: the highway-env id, or commonroad:<family>."""
        if self.env is not None:
            return self.env
        return recorded_env_id(recorded_files(self.commonroad, self.family, where)[1])

    def scenes(self, where: str = "scenario family") -> tuple[RecordedScene, ...] | None:
        """A recorded family's scenes, one per episode (parsed once per process); None for env."""
        if self.env is not None:
            return None
        return recorded_sweep(self.commonroad, self.family, self.t0, self.episodes, where)[1]

    def plain(self) -> dict:
        """Its config as plain values, without the other kind's keys (so that a highway-env
        family reads as it did before recorded families existed)."""
        plain = to_plain(self)
        for key in (_RECORDED_ONLY if self.env is not None else ("env", *_ENV_ONLY)):
            del plain[key]
        return plain


@dataclass(frozen=True)
class AttackConfig:
    name: str                         # registered attack (adversary.attacks.registry)
    label: str | None = None          # unique name in this campaign; default: name
    params: dict | None = None        # the attack's parameters (validated by its params type)
    envs: tuple[str, ...] = ()        # run only on scenario families of these env ids; empty: all

    def applies_to(self, env: str) -> bool:
        return not self.envs or env in self.envs


@dataclass(frozen=True)
class ReportConfig:
    gallery: int = 3                  # worst scenes shown with figures


@dataclass(frozen=True)
class CampaignConfig:
    name: str
    planners: tuple[str, ...]
    scenarios: tuple[ScenarioFamily, ...]
    attacks: tuple[AttackConfig, ...]
    seed: int = 0
    budget: Budget = field(default_factory=Budget)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    report: ReportConfig = field(default_factory=ReportConfig)

    def attack_params(self) -> dict[str, tuple[str, object]]:
        """label -> (attack name, validated params dataclass)."""
        out = {}
        for i, attack in enumerate(self.attacks):
            label = attack.label or attack.name
            out[label] = (attack.name, parse_attack_params(attack.name, attack.params,
                                                           f"attacks[{i}].params"))
        return out

    def plain(self) -> dict:
        """The config as plain values (campaign.json), each scenario family with its own keys."""
        plain = to_plain(self)
        plain["scenarios"] = [family.plain() for family in self.scenarios]
        return plain

    def env_ids(self) -> list[str]:
        """The env id of each scenario family, in order."""
        return [family.env_id() for family in self.scenarios]

    def jobs(self) -> list[Job]:
        attacks = self.attack_params()
        jobs = []
        for family, env_id in zip(self.scenarios, self.env_ids()):
            scenes = family.scenes()
            for planner in family.planners or self.planners:
                for episode in range(family.episodes):
                    for attack, (label, (name, params)) in zip(self.attacks, attacks.items()):
                        if not attack.applies_to(env_id):
                            continue
                        jobs.append(Job(planner, env_id, family.seed, episode, label, name,
                                        params, self.seed, self.budget, self.safety,
                                        scene=None if scenes is None else scenes[episode]))
        return jobs


def _validate(config: CampaignConfig, where: str = "campaign config") -> CampaignConfig:
    require(len(config.planners) >= 1, "campaign config: planners must list at least one SPEC")
    require(len(set(config.planners)) == len(config.planners), "campaign config: planners repeat a SPEC")
    display_names(config.planners)    # a bad or repeated name= fails with the config, not the report
    require(len(config.scenarios) >= 1, "campaign config: scenarios must list at least one family")
    require(len(config.attacks) >= 1, "campaign config: attacks must list at least one attack")
    labels = [a.label or a.name for a in config.attacks]
    duplicate = sorted({x for x in labels if labels.count(x) > 1})
    require(not duplicate, f"campaign config: attack label {duplicate[0] if duplicate else ''!r} is used "
                           "twice; give each variant its own label")
    for family in config.scenarios:
        extra = sorted(set(family.planners) - set(config.planners))
        require(not extra, f"scenario {family.name}: planner {extra[0] if extra else ''!r} is not in "
                           "the campaign's planners")
    envs = [family.env_id(f"{where}.scenarios[{i}]") for i, family in enumerate(config.scenarios)]
    recorded = [e for e in envs if recorded_family_of(e)]
    twice = sorted({e for e in recorded if recorded.count(e) > 1})
    require(not twice, f"{where}: two scenario families are the recorded family {twice[0] if twice else ''}; "
                       "list all its recordings under one family's commonroad")
    b = config.budget
    require(b.episode_s is None or b.episode_s > 0, f"budget.episode_s must be positive, got {b.episode_s}")
    require(b.control_hz >= 1 and b.replan_hz >= 1 and b.control_hz % b.replan_hz == 0,
            "budget: control_hz must be a positive multiple of replan_hz")
    s = config.safety
    require(s.close_gap_m >= 0 and s.ttc_s >= 0 and s.radius_m > 0 and s.off_road_margin_m >= 0,
            "safety: close_gap_m, ttc_s, off_road_margin_m must be >= 0 and radius_m > 0")
    require(config.report.gallery >= 0, "report.gallery must be >= 0")
    config.attack_params()            # validates every attack's params
    _validate_attack_envs(config, envs)
    for i, family in enumerate(config.scenarios):   # last: parses the recordings
        family.scenes(f"{where}.scenarios[{i}]")
    return config


def _validate_attack_envs(config: CampaignConfig, env_ids: list[str]) -> None:
    from adversary.attacks.registry import attack_entry
    from adversary.attacks.search import SEARCH_ENV_ID

    envs = set(env_ids)
    for i, attack in enumerate(config.attacks):
        unknown = sorted(set(attack.envs) - envs)
        require(not unknown, f"attacks[{i}].envs: {unknown[0] if unknown else ''!r} is not the env of "
                             "any scenario family")
        used = sorted(e for e in envs if attack.applies_to(e))
        require(bool(used), f"attacks[{i}] ({attack.name}) runs on no scenario family")
        recorded = [e for e in used if recorded_family_of(e)]
        if recorded and RECORDED not in attack_entry(attack.name).scenes:
            simulated = sorted(e for e in envs if not recorded_family_of(e))
            fix = (f"add envs: [{', '.join(simulated)}] to the attack" if simulated
                   else "remove the attack")
            raise InputError(f"attacks[{i}] ({attack.label or attack.name}) needs a highway-env world and "
                             f"cannot run on the recorded family {recorded[0]}; {fix}, or remove the family")
        if attack_entry(attack.name).category == "search":
            other = [e for e in used if e != SEARCH_ENV_ID]
            require(not other, f"attacks[{i}] ({attack.name}) searches a {SEARCH_ENV_ID} template and "
                               f"cannot run on {other[0] if other else ''}; add envs: [{SEARCH_ENV_ID}]")


def _scenario_keys(data, where: str):
    """The scenario families' keys checked for their kind (exactly one of env / commonroad, and
    only that kind's keys); a single commonroad path becomes a list of one."""
    if not isinstance(data, dict) or not isinstance(data.get("scenarios"), list):
        return data
    scenarios = []
    for i, family in enumerate(data["scenarios"]):
        here = f"{where}.scenarios[{i}]"
        if isinstance(family, dict):
            if ("env" in family) == ("commonroad" in family):
                raise InputError(f"{here}: give exactly one of env (a highway-env id) or commonroad "
                                 "(CommonRoad recordings: files, directories or globs)")
            kind, other = (("env", _RECORDED_ONLY) if "env" in family else ("commonroad", _ENV_ONLY))
            wrong = [key for key in other if key in family]
            if wrong:
                raise InputError(f"{here}: {wrong[0]} does not apply to a family with {kind}; remove it")
            if isinstance(family.get("commonroad"), str):
                family = {**family, "commonroad": [family["commonroad"]]}
        scenarios.append(family)
    return {**data, "scenarios": scenarios}


def campaign_from_dict(data, where: str = "campaign config") -> CampaignConfig:
    return _validate(from_mapping(CampaignConfig, _scenario_keys(data, where), where), where)


def load_campaign(path: Path) -> CampaignConfig:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"--config {path}: no such file; pass a campaign YAML "
                         "(see experiments/campaigns/)")
    try:
        data = yaml.safe_load(path.read_text())
    except UnicodeDecodeError:
        raise InputError(f"--config {path} is not a text file; pass a campaign YAML "
                         "(see experiments/campaigns/)") from None
    except yaml.YAMLError as error:
        raise InputError(f"--config {path}: not valid YAML ({str(error).splitlines()[0]}); fix its "
                         "syntax (see experiments/campaigns/ for examples)") from None
    if data is None:
        raise InputError(f"--config {path} is empty; write a campaign YAML (see "
                         "experiments/campaigns/)")
    return campaign_from_dict(data, f"campaign config {path}")
