"""Campaign config: what to stress-test, read from YAML into frozen, validated dataclasses.

    name: tiny                        # shown in the report
    seed: 0                           # planner sampling seed; attacks derive theirs from it
    planners: [cv, idm, riskmap:checkpoints/riskmap_highway]   # SPECs (riskmap.registry)
    scenarios:                        # scenario families: episodes 0..N-1 of `riskmap drive --seed`
      - {env: highway-v0, seed: 0, episodes: 2}
      - {env: intersection-v0, seed: 0, episodes: 2, planners: [idm]}   # optional subset
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
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import yaml

from adversary.attacks.monitor import SafetyConfig
from adversary.attacks.registry import parse_attack_params
from adversary.campaign.job import Budget, Job
from rasterize.config import family_of_env
from rasterize.errors import InputError
from riskmap.infra.config_mapping import from_mapping, require


@dataclass(frozen=True)
class ScenarioFamily:
    env: str                          # highway-env id
    seed: int = 0                     # scene seed (riskmap drive --seed)
    episodes: int = 1                 # episodes 0..episodes-1 of that seed
    planners: tuple[str, ...] = ()    # empty: every planner of the campaign

    def __post_init__(self) -> None:
        family_of_env(self.env)       # an InputError naming the supported ids
        require(self.episodes >= 1, f"scenario {self.env}: episodes must be >= 1, got {self.episodes}")
        require(self.seed >= 0, f"scenario {self.env}: seed must be >= 0, got {self.seed}")


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

    def jobs(self) -> list[Job]:
        attacks = self.attack_params()
        jobs = []
        for family in self.scenarios:
            for planner in family.planners or self.planners:
                for episode in range(family.episodes):
                    for attack, (label, (name, params)) in zip(self.attacks, attacks.items()):
                        if not attack.applies_to(family.env):
                            continue
                        jobs.append(Job(planner, family.env, family.seed, episode, label, name,
                                        params, self.seed, self.budget, self.safety))
        return jobs


def _validate(config: CampaignConfig) -> CampaignConfig:
    require(len(config.planners) >= 1, "campaign config: planners must list at least one SPEC")
    require(len(set(config.planners)) == len(config.planners), "campaign config: planners repeat a SPEC")
    require(len(config.scenarios) >= 1, "campaign config: scenarios must list at least one family")
    require(len(config.attacks) >= 1, "campaign config: attacks must list at least one attack")
    labels = [a.label or a.name for a in config.attacks]
    duplicate = sorted({x for x in labels if labels.count(x) > 1})
    require(not duplicate, f"campaign config: attack label {duplicate[0] if duplicate else ''!r} is used "
                           "twice; give each variant its own label")
    for family in config.scenarios:
        extra = sorted(set(family.planners) - set(config.planners))
        require(not extra, f"scenario {family.env}: planner {extra[0] if extra else ''!r} is not in "
                           "the campaign's planners")
    b = config.budget
    require(b.episode_s is None or b.episode_s > 0, f"budget.episode_s must be positive, got {b.episode_s}")
    require(b.control_hz >= 1 and b.replan_hz >= 1 and b.control_hz % b.replan_hz == 0,
            "budget: control_hz must be a positive multiple of replan_hz")
    s = config.safety
    require(s.close_gap_m >= 0 and s.ttc_s >= 0 and s.radius_m > 0 and s.off_road_margin_m >= 0,
            "safety: close_gap_m, ttc_s, off_road_margin_m must be >= 0 and radius_m > 0")
    require(config.report.gallery >= 0, "report.gallery must be >= 0")
    config.attack_params()            # validates every attack's params
    _validate_attack_envs(config)
    return config


def _validate_attack_envs(config: CampaignConfig) -> None:
    from adversary.attacks.registry import attack_entry
    from adversary.attacks.search import SEARCH_ENV_ID

    envs = {family.env for family in config.scenarios}
    for i, attack in enumerate(config.attacks):
        unknown = sorted(set(attack.envs) - envs)
        require(not unknown, f"attacks[{i}].envs: {unknown[0] if unknown else ''!r} is not the env of "
                             "any scenario family")
        used = sorted(e for e in envs if attack.applies_to(e))
        require(bool(used), f"attacks[{i}] ({attack.name}) runs on no scenario family")
        if attack_entry(attack.name).category == "search":
            other = [e for e in used if e != SEARCH_ENV_ID]
            require(not other, f"attacks[{i}] ({attack.name}) searches a {SEARCH_ENV_ID} template and "
                               f"cannot run on {other[0] if other else ''}; add envs: [{SEARCH_ENV_ID}]")


def campaign_from_dict(data, where: str = "campaign config") -> CampaignConfig:
    return _validate(from_mapping(CampaignConfig, data, where))


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
