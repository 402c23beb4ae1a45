"""The report's recording wrapper changes nothing the rollout reads from the planner it wraps."""

from adversary.attacks.episode import RecordingPlanner
from riskmap.sim.loop.plan import requires_log
from tests.adversary.attacks.conftest import NeverPlans


class _Declares(NeverPlans):
    requires_log = True
    name = "declares"

    def __init__(self):
        self.attached, self.log = None, None

    def attach(self, run):
        self.attached = run

    def set_log(self, log):
        self.log = log


def test_the_wrapper_forwards_attach_and_the_log_declarations():
    inner = _Declares()
    wrapped = RecordingPlanner(inner)
    assert requires_log(wrapped) and wrapped.name == "declares"
    assert hasattr(wrapped, "attach")      # the rollout calls attach(world) only if it exists
    wrapped.attach("world")
    wrapped.set_log("log")
    assert inner.attached == "world" and inner.log == "log"
    assert not hasattr(RecordingPlanner(object()), "attach")
