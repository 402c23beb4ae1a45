"""The space-time risk-map generator: one reward map per future step (DESIGN §3b).

    raster [B, C, 200, 200] ─ ResNet-34 stem + layer1 + conv ─► features [B, 64, G, G]
    features ⊕ motion [B, 3, G, G] ─ 1×1 conv ─────────────────► base [B, h, G, G]     (once)
    evidence_t [B, E, G, G] ⊕ t/T ─ 3×3 conv ──────────────────► step_t [B, h, G, G]   (per step)
    ReLU(base + step_t) ─ 1×1 convs h→h→1 ─ LogSigmoid ────────► r_t [B, G, G] ≤ 0,  t = 1 … T
    features ⊕ motion ⊕ route goal [B, 1, G, G] ─ 1×1 conv ─ LogSigmoid ─► g [B, G, G] ≤ 0

The encoder and the layers of the head are the spatial generator's (`RiskMapGenerator`, the
paper's): its first 1×1 convolution splits into the part that reads the features and motion
(computed once per plan, not T times) and the part that reads each step's evidence (the other
agents' predicted footprints and the red stop lines at step t, `rasterize.spacetime`) and the
time t/T. The 3×3 kernel lets a cell see an agent predicted in the cell next to it. Initialised
from a spatial checkpoint with the step part at zero, it computes that checkpoint's risk map at
every step, and training adds when.

The goal map g (the value of ending the 6 s in a cell) is learned too, from the route rule's
goal (a Gaussian in [0, 1], `rasterize.maps.goal_map`) and the features. A fixed route goal
fixes the speed: every path must end near it at step T, and a wait that leaves the ego 20 cells
short costs 20²/(2σ²) = 40 nats at σ² = 5, more than any step's reward can pay back. Learned, g
can say "the route goal, unless the way there is about to be taken". It starts as
logsigmoid(20 · route goal − 10): 0 on the route goal, −10 far from it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from rasterize.errors import InputError
from rasterize.spacetime import EVIDENCE_CHANNELS
from riskmap.planner.model import ModelConfig, RiskMapGenerator
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS

PLANNER_KIND = "spacetime"            # a checkpoint sidecar's `planner` (absent: the spatial one)
MAX_FORWARD_CELLS = 16                # K beyond this is no longer a step of one vehicle
MAX_ACROSS_CELLS = 8


@dataclass(frozen=True)
class SpaceTimeConfig:
    """T steps of `step_s` seconds covering the plan's 6 s; per step the ego moves 0 … K =
    `max_forward` rows forward and −L … +L = `max_across` columns across (cells)."""

    steps: int = PLAN_STEPS
    max_forward: int = 4
    max_across: int = 1

    def __post_init__(self) -> None:
        if not isinstance(self.steps, int) or self.steps < 1 or PLAN_STEPS % self.steps:
            raise InputError(f"--steps {self.steps!r}: space-time steps must divide the plan's "
                             f"{PLAN_STEPS} waypoints (1, 2, 3, 4, 6 or 12)")
        if not isinstance(self.max_forward, int) or not 1 <= self.max_forward <= MAX_FORWARD_CELLS:
            raise InputError(f"--max-forward {self.max_forward!r}: must be 1 … {MAX_FORWARD_CELLS} "
                             "cells per step")
        if not isinstance(self.max_across, int) or not 0 <= self.max_across <= MAX_ACROSS_CELLS:
            raise InputError(f"--max-across {self.max_across!r}: must be 0 … {MAX_ACROSS_CELLS} "
                             "cells per step")

    @property
    def step_s(self) -> float:
        """Seconds per step: the plan's 6 s over T."""
        return PLAN_STEPS * PLAN_DT_S / self.steps

    def to_dict(self) -> dict:
        return asdict(self)


class SpaceTimeRiskMapGenerator(RiskMapGenerator):
    """(raster [B, C, H, W], motion [B, 3, G, G], evidence [B, T, E, G, G]) → rewards [B, T, G, G]."""

    def __init__(self, config: ModelConfig, spacetime: SpaceTimeConfig):
        if config.timing_head:
            raise InputError("the space-time planner times its plan itself; drop --timing-head")
        super().__init__(config)
        self.spacetime = spacetime
        h = config.head_channels
        self.head = nn.ModuleDict({
            "base": nn.Conv2d(config.encoder_channels + 3, h, 1),
            "step": nn.Conv2d(len(EVIDENCE_CHANNELS) + 1, h, 3, padding=1, bias=False),
            "rest": nn.Sequential(nn.ReLU(inplace=True), nn.Conv2d(h, h, 1), nn.ReLU(inplace=True),
                                  nn.Conv2d(h, 1, 1)),
            "goal": nn.Conv2d(config.encoder_channels + 3 + 1, 1, 1),
        })
        _route_goal_start(self.head["goal"])

    def _features(self, raster: torch.Tensor, evidence: torch.Tensor) -> torch.Tensor:
        """The encoder's features at the grid's resolution [B, C, G, G], once the evidence's
        shape is checked (InputError naming the expected shape otherwise)."""
        g, steps = self.config.resolution, self.spacetime.steps
        if evidence.shape[1:] != (steps, len(EVIDENCE_CHANNELS), g, g):
            raise InputError(f"evidence must be [B, {steps}, {len(EVIDENCE_CHANNELS)}, {g}, {g}], "
                             f"got {tuple(evidence.shape)}")
        features = self.encoder_conv(self.backbone(raster))
        if features.shape[-2:] != (g, g):
            mode = "area" if features.shape[-1] > g else "bilinear"
            features = F.interpolate(features, size=(g, g), mode=mode,
                                     **({} if mode == "area" else {"align_corners": False}))
        return features

    def forward(self, raster: torch.Tensor, motion: torch.Tensor, evidence: torch.Tensor,
                route_goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(rewards r_1 … r_T [B, T, G, G], goal map g [B, G, G]), both ≤ 0 (log space);
        route_goal [B, G, G] is the route rule's goal map in [0, 1]."""
        g, steps = self.config.resolution, self.spacetime.steps
        b = raster.shape[0]
        features = self._features(raster, evidence)
        inputs = torch.cat([features, motion], dim=1)
        base = self.head["base"](inputs)                                        # [B, h, G, G]
        goal = F.logsigmoid(self.head["goal"](torch.cat([inputs, route_goal[:, None]], dim=1)))
        time = torch.arange(1, steps + 1, dtype=evidence.dtype, device=evidence.device) / steps
        time = time.view(1, steps, 1, 1, 1).expand(b, steps, 1, g, g)
        step_in = torch.cat([evidence, time], dim=2).flatten(0, 1)             # [B T, E + 1, G, G]
        step_in = step_in.contiguous(memory_format=torch.channels_last) \
            if base.is_contiguous(memory_format=torch.channels_last) else step_in
        hidden = self.head["step"](step_in).unflatten(0, (b, steps)) + base[:, None]
        logits = self.head["rest"](hidden.flatten(0, 1)).view(b, steps, g, g)
        return F.logsigmoid(logits), goal[:, 0]

    @torch.inference_mode()
    def planning_maps(self, raster: torch.Tensor, motion: torch.Tensor, evidence: torch.Tensor,
                      route_goal: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """`forward`'s (rewards, goal map) for planning, without autograd: the same encoder and
        step convolution, and the head's 1×1 layers as matrix products over the [T G², h]
        channels-last pixels, in place. forward runs them as 1×1 convolutions on [B T, h, G, G],
        which on one CPU thread go through torch's slow unfolding path (a bias copy, a strided
        add, then the product): the 50×50 head took 6.6 ms there, 5.2 here, the same numbers
        bit for bit on one thread (experiments/README.md, "Space-time plan latency")."""
        g, steps = self.config.resolution, self.spacetime.steps
        b = raster.shape[0]
        features = self._features(raster, evidence)
        head, pixels = self.head, g * g
        base_w, base_b = _matrix(head["base"]), head["base"].bias
        goal_w, goal_b = _matrix(head["goal"]), head["goal"].bias
        hidden_w, hidden_b = _matrix(head["rest"][1]), head["rest"][1].bias
        out_w, out_b = _matrix(head["rest"][3]), head["rest"][3].bias
        time = torch.arange(1, steps + 1, dtype=evidence.dtype, device=evidence.device) / steps
        time = time.view(1, steps, 1, 1, 1).expand(b, steps, 1, g, g)
        step_in = torch.cat([evidence, time], dim=2).flatten(0, 1)             # [B T, E + 1, G, G]
        # The 3×3 step convolution as forward runs it (oneDNN is fastest on channels-last),
        # its output read as [B, T, G², h] channels-last pixels.
        steps_out = head["step"](step_in.contiguous(memory_format=torch.channels_last))
        steps_out = steps_out.permute(0, 2, 3, 1).reshape(b, steps, pixels, -1)
        rewards = features.new_empty((b, steps * pixels, 1))
        goals = features.new_empty((b, pixels, 1))
        for i in range(b):
            inputs = torch.cat([features[i].permute(1, 2, 0), motion[i].permute(1, 2, 0)],
                               dim=2).reshape(pixels, -1)                  # [G², C + 3]
            base = torch.addmm(base_b, inputs, base_w)                      # [G², h]
            torch.addmm(goal_b, torch.cat([inputs, route_goal[i].reshape(pixels, 1)], dim=1),
                        goal_w, out=goals[i])
            hidden = steps_out[i].add_(base).relu_().view(steps * pixels, -1)  # [T G², h]
            hidden = torch.addmm(hidden_b, hidden, hidden_w).relu_()
            torch.addmm(out_b, hidden, out_w, out=rewards[i])
        return F.logsigmoid(rewards).view(b, steps, g, g), F.logsigmoid(goals).view(b, g, g)


def _matrix(conv: nn.Conv2d) -> torch.Tensor:
    """A 1×1 convolution's weight as the [in, out] matrix that multiplies channels-last pixels."""
    return conv.weight[:, :, 0, 0].t()


ROUTE_GOAL_GAIN, ROUTE_GOAL_OFFSET = 20.0, -10.0     # the goal head's start (module docstring)


def _route_goal_start(conv: nn.Conv2d) -> None:
    """The goal head computing logsigmoid(20 · route goal − 10): the route channel is the last."""
    with torch.no_grad():
        conv.weight.zero_()
        conv.weight[0, -1] = ROUTE_GOAL_GAIN
        conv.bias.fill_(ROUTE_GOAL_OFFSET)


def state_from_spatial(model: SpaceTimeRiskMapGenerator, spatial_state: dict) -> dict:
    """`model`'s state dict started from a spatial checkpoint's: the encoder as trained, the
    head's layers as the spatial head's, the per-step part at zero (so the network computes the
    spatial risk map at every step until training teaches it otherwise)."""
    state = model.state_dict()
    for key, value in spatial_state.items():
        if key.startswith(("backbone.", "encoder_conv.")):
            state[key] = value
    mapping = {"head.0.": "head.base.", "head.2.": "head.rest.1.", "head.4.": "head.rest.3."}
    for key, value in spatial_state.items():
        for old, new in mapping.items():
            if key.startswith(old):
                state[new + key[len(old):]] = value
    state["head.step.weight"] = torch.zeros_like(state["head.step.weight"])
    return state


def is_spacetime(sidecar: dict) -> bool:
    """Whether a risk-map checkpoint's sidecar is the space-time planner's."""
    return sidecar.get("planner") == PLANNER_KIND


def load_spacetime_model(path: Path, device: str = "cpu"
                         ) -> tuple[SpaceTimeRiskMapGenerator, dict]:
    """The trained space-time generator (eval mode) and its sidecar; a spatial checkpoint is an
    InputError naming it."""
    from rasterize.config import RasterConfig
    from riskmap.infra.checkpoint import load_weights, read_sidecar, sidecar_section

    side = read_sidecar(Path(path))
    if not is_spacetime(side):
        raise InputError(f"checkpoint {path} is a spatial risk-map planner; this needs a "
                         "space-time one (`riskmap train --planner spacetime`)")
    model = SpaceTimeRiskMapGenerator(sidecar_section(side, "model", path, ModelConfig),
                                      sidecar_section(side, "spacetime", path, SpaceTimeConfig))
    model = load_weights(model, Path(path), "it was made by an incompatible version")
    sidecar_section(side, "raster", path, lambda **d: RasterConfig.from_dict(d))
    return model.to(device).eval(), side
