"""The risk-aware planner: demonstrations, dataset, risk-map generator, value iteration, IRL
training, sampler, planner and closed-loop driving. Heavy modules (torch) load on first use."""

# name: the module that defines it (tests/riskmap/test_public_names.py imports every one)
_LAZY = {
    "Plan": "riskmap.sim.loop.plan", "Planner": "riskmap.sim.loop.plan", "PLAN_STEPS": "riskmap.sim.loop.plan",
    "PLAN_DT_S": "riskmap.sim.loop.plan", "NoSolution": "riskmap.sim.loop.plan",
    "RiskMapPlanner": "riskmap.planner.riskmap_planner", "load_planner": "riskmap.planner.riskmap_planner",
    "SpaceTimePlanner": "riskmap.planner.st_planner",
    "DemoDataset": "riskmap.data.dataset", "make_planner": "riskmap.registry",
    "make_env": "riskmap.sim.worlds.episode", "drive_episode": "riskmap.sim.worlds.highway_drive",
    "soft_value_iteration": "riskmap.planner.vi", "state_visitation": "riskmap.planner.vi",
}

__all__ = sorted(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(name)
