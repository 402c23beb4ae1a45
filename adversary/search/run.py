"""`adversary search`: black-box search for scenario conditions that make the ego collide.

NSGA-II (pymoo) over a template's parameter vector, each candidate evaluated in closed loop in
highway-env with the ego driven by a planner SPEC; random search with the same budget (pymoo's
random sampling, one batch of `pop` per generation) is the baseline. Objectives, the collision
flag and the braking-distance constraint are those of `adversary.search.objectives` (see its docstring
for how the flag is made well defined for NSGA-II).

Storage, under OUT:
    run.json                      the resolved configuration and provenance
    evaluations/<key>.json        one per evaluated parameter vector, written atomically as
                                  soon as it finishes; key = hash of the exact float64 vector
    generations/gen_NNN.json      the keys evaluated in generation NNN, written when it ends
Resume: the algorithms are seeded, so a rerun asks for exactly the same vectors; every vector
whose evaluation file exists is read back instead of being driven again.

Parallel evaluation: pymoo's elementwise runner over a process pool (`--workers K`), or over Ray
tasks (`--backend ray [--address ADDR]`); each worker builds its planner and env once.

`search_in_process(config)` runs the same generations in the calling process without storing
anything and returns a `SearchOutcome` (per-generation collisions, the Pareto front, the most
critical vector); the campaign's search attacks (adversary.attacks.search) call it.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from pymoo.core.problem import ElementwiseProblem

from adversary.search.evaluation import EvaluationConfig, constraint_value, evaluate
from adversary.search.objectives import (
    OBJECTIVE_NAMES,
    collided_from_objectives,
    scene_alteration,
    unpenalised,
)
from adversary.search.scenarios import Template, get_template
from rasterize.errors import InputError
from riskmap.infra.atomic import write_json
from riskmap.infra.provenance import provenance
from riskmap.infra.rundir import check_same_settings, lock_out_dir, refuse_unless_resume

ALGORITHMS = ("nsga2", "random")


@dataclass(frozen=True)
class SearchConfig:
    planner: str
    template: str
    algorithm: str = "nsga2"
    pop: int = 20                   # evaluations per generation
    gen: int = 10                   # generations; the budget is pop × gen evaluations
    seed: int = 0
    episode_s: float = 10.0         # simulated seconds per evaluation
    workers: int = 1                # evaluation processes

    def __post_init__(self) -> None:
        if self.algorithm not in ALGORITHMS:
            raise InputError(f"--algorithm {self.algorithm!r}: use one of {', '.join(ALGORITHMS)}")
        if self.pop < 2 or self.gen < 1:
            raise InputError(f"--pop must be ≥ 2 and --gen ≥ 1, got {self.pop} and {self.gen}")
        if self.workers < 1:
            raise InputError(f"--workers must be ≥ 1, got {self.workers}")
        if not (self.episode_s < float("inf") and self.evaluation.steps >= 1):
            raise InputError(f"--episode-s must be a finite number of seconds ≥ "
                             f"{0.5 / self.evaluation.control_hz:g}, got {self.episode_s}")
        get_template(self.template)

    @property
    def evaluation(self) -> EvaluationConfig:
        return EvaluationConfig(self.planner, self.template, self.seed, self.episode_s)


def evaluation_key(x: np.ndarray) -> str:
    """Stable name of one exact parameter vector."""
    return hashlib.sha1(np.asarray(x, dtype=np.float64).tobytes()).hexdigest()[:16]


class ScenarioProblem(ElementwiseProblem):
    """n_var = template parameters, F [3] (objectives module), G [1] braking constraint.

    An evaluation already stored under `store` is read back instead of being driven again;
    store None: nothing is stored.
    """

    def __init__(self, template: Template, config: EvaluationConfig, store: Path | None, **kwargs):
        super().__init__(n_var=len(template.parameters), n_obj=len(OBJECTIVE_NAMES), n_ieq_constr=1,
                         xl=template.lower, xu=template.upper, **kwargs)
        self.template, self.config = template, config
        self.store = None if store is None else Path(store)

    def _evaluate(self, x, out, *args, **kwargs):
        path = None if self.store is None else self.store / f"{evaluation_key(x)}.json"
        if path is not None and path.exists():
            record = json.loads(path.read_text())
        else:
            record = evaluate(self.template, x, self.config)
            if path is not None:
                write_json(path, record)
        out["F"] = np.asarray(record["F"])
        out["G"] = np.array([record["G"]])


def _worker_init() -> None:
    import torch

    torch.set_num_threads(1)      # one core per evaluation process


def _random_batch(problem, n: int, rng: np.random.Generator, template: Template) -> np.ndarray:
    """`n` vectors from pymoo's uniform random sampling that satisfy the constraint (rejection),
    so that the baseline spends its whole budget on scenes solvable in principle."""
    from pymoo.operators.sampling.rnd import FloatRandomSampling

    sampling, kept = FloatRandomSampling(), []
    for _ in range(1000):
        pop = sampling.do(problem, n, random_state=rng)
        kept.extend(x for x in pop.get("X") if constraint_value(template, x) <= 0)
        if len(kept) >= n:
            return np.asarray(kept[:n])
    raise InputError(f"template {template.name}: random sampling found no feasible vector")


def _check_out(out: Path, config: SearchConfig, resume: bool) -> None:
    refuse_unless_resume(out, "evaluations", "evaluations", resume)
    lock_out_dir(out)   # one writer per search directory (creates it)
    if resume:
        check_same_settings(out, "run.json", {"config": asdict(config)}, may_change=("config.workers",))


def _ray_call(function, args):
    _worker_init()
    return function(*args)


def _ray_starmap():
    """A `starmap(f, iterable)` that runs each call as a Ray task (one CPU each), in order."""
    import ray

    remote = ray.remote(num_cpus=1)(_ray_call)
    return lambda function, iterable: ray.get([remote.remote(function, args) for args in iterable])


def generations(problem: ScenarioProblem, config: SearchConfig):
    """Yield each generation's evaluated pymoo Population (X [pop, n_var], F [pop, 3], G [pop, 1])
    in order; the search is seeded by `config.seed`, so the same config yields the same vectors."""
    from pymoo.algorithms.moo.nsga2 import NSGA2
    from pymoo.core.evaluator import Evaluator
    from pymoo.core.population import Population

    evaluator = Evaluator()
    rng = np.random.default_rng(config.seed)
    if config.algorithm == "nsga2":
        algorithm = NSGA2(pop_size=config.pop, eliminate_duplicates=True)
        algorithm.setup(problem, termination=("n_gen", config.gen), seed=config.seed)
    for _ in range(config.gen):
        if config.algorithm == "nsga2":
            batch = algorithm.ask()
        else:
            batch = Population.new("X", _random_batch(problem, config.pop, rng, problem.template))
        evaluator.eval(problem, batch)
        if config.algorithm == "nsga2":
            algorithm.tell(infills=batch)
        yield batch


@dataclass(frozen=True)
class SearchOutcome:
    """What one search found. Objective rows are the scaled objectives without the collision
    penalty (objectives.OBJECTIVE_NAMES), so that failures and near misses share one scale."""

    generations: tuple[dict, ...]      # per generation {"evaluations": n, "collisions": k}
    pareto_front: tuple[tuple[float, ...], ...]   # [m, 3] first front of the feasible evaluations
    front_collided: tuple[bool, ...]   # [m] whether each front member collided
    best_x: tuple[float, ...]          # the most critical vector (`most_critical`)
    best_collided: bool
    evaluations: int

    def extra(self, template: Template) -> dict:
        """JSON-ready `attack_extra` of a campaign record (the report reads the first three)."""
        return {"generations": list(self.generations),
                "pareto_front": [list(row) for row in self.pareto_front],
                "objective_names": list(OBJECTIVE_NAMES),
                "front_collided": list(self.front_collided),
                "best_params": template.as_dict(np.asarray(self.best_x)),
                "best_collided": self.best_collided,
                "evaluations": self.evaluations}


def most_critical(F: np.ndarray, G: np.ndarray, alteration: np.ndarray) -> int:
    """Index of the most critical evaluation: a feasible collision if there is one, the least
    altered among them (the search report's choice); else the feasible evaluation with the
    smallest sum of scaled objectives (the nearest miss). Ties: the first evaluated.
    F [n, 3] penalised, G [n] constraint, alteration [n]."""
    feasible = np.flatnonzero(G <= 0)
    if len(feasible) == 0:
        raise InputError("the search found no feasible scenario; raise pop or generations")
    collided = collided_from_objectives(F[feasible])
    if collided.any():
        failures = feasible[collided]
        return int(failures[np.argmin(alteration[failures])])
    return int(feasible[np.argmin(F[feasible].sum(axis=1))])


def search_in_process(config: SearchConfig) -> SearchOutcome:
    """Run the search in this process (no files, no progress bar); see `SearchOutcome`."""
    from pymoo.util.nds.non_dominated_sorting import NonDominatedSorting

    template = get_template(config.template)
    problem = ScenarioProblem(template, config.evaluation, store=None)
    xs, fs, gs, counts = [], [], [], []
    for batch in generations(problem, config):
        x, f, g = batch.get("X"), batch.get("F"), batch.get("G")[:, 0]
        feasible = g <= 0
        counts.append({"evaluations": len(x),
                       "collisions": int(collided_from_objectives(f[feasible]).sum())})
        xs.append(x)
        fs.append(f)
        gs.append(g)
    X, F, G = np.concatenate(xs), np.concatenate(fs), np.concatenate(gs)
    alteration = np.array([scene_alteration(x, template.neutral, template.lower, template.upper)
                           for x in X])
    best = most_critical(F, G, alteration)
    feasible = np.flatnonzero(G <= 0)
    front = feasible[NonDominatedSorting().do(F[feasible], only_non_dominated_front=True)]
    front = front[np.lexsort(F[front].T[::-1])]       # a fixed order: by f1, then f2, f3
    collided = collided_from_objectives(F)
    return SearchOutcome(
        generations=tuple(counts),
        pareto_front=tuple(tuple(float(v) for v in unpenalised(F[i])) for i in front),
        front_collided=tuple(bool(collided[i]) for i in front),
        best_x=tuple(float(v) for v in X[best]), best_collided=bool(collided[best]),
        evaluations=len(X))


def search(config: SearchConfig, out: Path, resume: bool = False, progress: bool = True,
           frames: bool = True, backend: str = "local", address: str | None = None) -> dict:
    """Run the search; returns the summary (also OUT/summary.json, with figures under OUT).

    backend "local": a process pool of `config.workers` (none for 1); "ray": Ray tasks on the
    cluster at `address` or on a local Ray instance. Results do not depend on the backend."""
    if backend not in ("local", "ray"):
        raise InputError(f"--backend must be local or ray, got {backend!r}")
    from multiprocessing import get_context

    from pymoo.parallelization.starmap import StarmapParallelization
    from tqdm import tqdm

    from adversary.search.report import write_report
    from riskmap.registry import display_name, make_planner

    out = Path(out)
    make_planner(config.planner, seed=config.seed)   # a bad SPEC fails here, before --out exists
    _check_out(out, config, resume)
    write_json(out / "run.json", {"config": asdict(config), **provenance()})
    template = get_template(config.template)
    pool = None
    ray_started = False
    kwargs = {}
    if backend == "ray":
        from riskmap.infra.parallel import init_ray

        ray_started = init_ray(config.workers, address)
        kwargs["elementwise_runner"] = StarmapParallelization(_ray_starmap())
    elif config.workers > 1:
        pool = get_context("spawn").Pool(config.workers, initializer=_worker_init)
        kwargs["elementwise_runner"] = StarmapParallelization(pool.starmap)
    else:
        _worker_init()
    problem = ScenarioProblem(template, config.evaluation, out / "evaluations", **kwargs)
    try:
        batches = generations(problem, config)
        for generation, batch in enumerate(tqdm(batches, total=config.gen, disable=not progress,
                                                desc=f"{config.algorithm} {display_name(config.planner)} "
                                                     f"{config.template}")):
            keys = [evaluation_key(x) for x in batch.get("X")]
            write_json(out / "generations" / f"gen_{generation:03d}.json",
                       {"generation": generation, "keys": keys})
    finally:
        if pool is not None:
            pool.close()
            pool.join()
        if ray_started:
            import ray

            ray.shutdown()
    return write_report(out, frames=frames)
