"""The risk-aware planner: demonstrations, dataset, risk-map generator, value iteration, IRL
training, sampler, planner and closed-loop driving. Heavy modules (torch) load on first use."""

_LAZY = {
    "RiskMapPlanner": "riskmap.planner.riskmap_planner", "Plan": "riskmap.planner.riskmap_planner", "Planner": "riskmap.planner.riskmap_planner",
    "DemoDataset": "riskmap.data.dataset", "make_planner": "riskmap.registry",
    "soft_value_iteration": "riskmap.planner.vi", "state_visitation": "riskmap.planner.vi",
}

__all__ = sorted(_LAZY)


def __getattr__(name):
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(name)
