"""The risk-map generator (planner paper §IV-A, P2T's layout).

    raster [B, C, 200, 200] ─ ResNet-34 stem + layer1 ─► [B, 64, 50, 50] ─ conv ─► resize to G×G
    ─ concat motion features [B, 3, G, G] ─ 1×1 convs 67→32→32→1 ─ LogSigmoid ─► risk [B, G, G]

With `timing_head` (our addition; the paper's planner has no notion of time along its path), the
same encoder features, detached, also feed

    [B, 64, G', G'] ─ 2 strided 3×3 convs ─ pool 6×6 ─ MLP (+ ego speed) ─► arc lengths [B, 12]

the distance along its path the ego covers by each of the 12 waypoint times (0.5 s apart),
learned from the demonstrations' own futures (`timing_loss`). Detached, so the risk map stays
exactly what MaxEnt IRL makes of the data: the head reads it, never bends it.

Rewards are ≤ 0 (LogSigmoid). The stem's first convolution takes the raster's C channels;
`load_backbone_weights` adapts a local torchvision ResNet-34 state dict (never a hub download).
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn
from torchvision.models import resnet34

from rasterize.config import RasterConfig
from rasterize.errors import InputError
from riskmap.infra.checkpoint import load_weights, read_sidecar, sidecar_section
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS


@dataclass(frozen=True)
class ModelConfig:
    in_channels: int = 8          # raster channels
    resolution: int = 50          # risk-map grid G (25, 50, 75, 100 ...)
    encoder_channels: int = 64    # after the extra conv
    head_channels: int = 32
    timing_head: bool = False     # also predict the arc lengths of the 12 waypoints (`TimingHead`)

    def to_dict(self) -> dict:
        return asdict(self)


SPEED_SCALE_MPS = 30.0            # speed input and outputs divided by this: numbers of order 1


class TimingHead(nn.Module):
    """Encoder features [B, C, G', G'] and ego speed [B] (m/s) → arc lengths [B, 12] (m), never
    decreasing, at 0.5 s steps.

    The head predicts one speed per step as softplus(z · 30 m/s + softplus⁻¹(v)): an output of
    zero is the ego's present speed held (the few epochs a CPU affords start from a sensible
    drive), a speed is never negative, and the arc lengths are their running sum × 0.5 s."""

    def __init__(self, channels: int, hidden: int = 128):
        super().__init__()
        self.reduce = nn.Sequential(
            nn.Conv2d(channels, 32, kernel_size=3, stride=2, padding=1), nn.ReLU(inplace=True),
            nn.Conv2d(32, 32, kernel_size=3, stride=2, padding=1), nn.ReLU(inplace=True),
            nn.AdaptiveAvgPool2d(6), nn.Flatten(),
        )
        self.mlp = nn.Sequential(nn.Linear(32 * 36 + 1, hidden), nn.ReLU(inplace=True),
                                 nn.Linear(hidden, PLAN_STEPS))
        nn.init.zeros_(self.mlp[-1].weight)      # starts at constant speed
        nn.init.zeros_(self.mlp[-1].bias)

    def forward(self, features: torch.Tensor, speed: torch.Tensor) -> torch.Tensor:
        speed = speed.clamp_min(0.1)             # softplus⁻¹ needs a positive speed
        z = self.mlp(torch.cat([self.reduce(features), (speed / SPEED_SCALE_MPS)[:, None]], dim=1))
        held = speed + torch.log(-torch.expm1(-speed))               # softplus⁻¹(v), stable
        speeds = F.softplus(z * SPEED_SCALE_MPS + held[:, None])      # [B, 12] m/s
        return PLAN_DT_S * speeds.cumsum(dim=1)


def timing_loss(arc_lengths: torch.Tensor, future: torch.Tensor) -> torch.Tensor:
    """Mean Huber loss (1 m) between predicted arc lengths [B, 12] and the demonstrations' own:
    the length of the recorded future [B, 12, 2] (ego frame, m) from the ego to each waypoint."""
    return F.smooth_l1_loss(arc_lengths, demo_arc_lengths(future), beta=1.0)


def demo_arc_lengths(future: torch.Tensor) -> torch.Tensor:
    """[B, 12] distance along the recorded future [B, 12, 2] from the ego (the origin) to each
    waypoint, metres."""
    line = torch.cat([torch.zeros_like(future[:, :1]), future], dim=1)
    return torch.linalg.vector_norm(line.diff(dim=1), dim=-1).cumsum(dim=1)


class RiskMapGenerator(nn.Module):
    def __init__(self, config: ModelConfig = ModelConfig()):
        super().__init__()
        if config.resolution < 2:
            raise InputError(f"resolution must be >= 2 cells, got {config.resolution}")
        self.config = config
        resnet = resnet34(weights=None)
        resnet.conv1 = nn.Conv2d(config.in_channels, 64, kernel_size=7, stride=2, padding=3,
                                 bias=False)
        self.backbone = nn.Sequential(resnet.conv1, resnet.bn1, resnet.relu, resnet.maxpool,
                                      resnet.layer1)
        self.encoder_conv = nn.Sequential(
            nn.Conv2d(64, config.encoder_channels, kernel_size=3, padding=1), nn.ReLU(inplace=True)
        )
        c = config.encoder_channels + 3
        self.head = nn.Sequential(
            nn.Conv2d(c, config.head_channels, 1), nn.ReLU(inplace=True),
            nn.Conv2d(config.head_channels, config.head_channels, 1), nn.ReLU(inplace=True),
            nn.Conv2d(config.head_channels, 1, 1),
        )
        self.timing = TimingHead(config.encoder_channels) if config.timing_head else None

    def forward(self, raster: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
        """raster [B, C, H, W], motion [B, 3, G, G] → risk map [B, G, G] (≤ 0)."""
        return self._risk(self.encoder_conv(self.backbone(raster)), motion)

    def forward_timed(self, raster: torch.Tensor, motion: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor]:
        """(risk map [B, G, G], arc lengths [B, 12] m): the timing head reads the same features,
        detached (module doc); motion's first channel is the ego's speed."""
        if self.timing is None:
            raise InputError("this risk-map network has no timing head; train one with --timing-head")
        features = self.encoder_conv(self.backbone(raster))
        return self._risk(features, motion), self.timing(features.detach(), motion[:, 0, 0, 0])

    def _risk(self, features: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
        g = self.config.resolution
        if features.shape[-2:] != (g, g):
            mode = "area" if features.shape[-1] > g else "bilinear"
            features = F.interpolate(features, size=(g, g), mode=mode,
                                     **({} if mode == "area" else {"align_corners": False}))
        logits = self.head(torch.cat([features, motion], dim=1)).squeeze(1)
        return F.logsigmoid(logits)


def for_inference(model: RiskMapGenerator) -> RiskMapGenerator:
    """A copy of `model` made for planning, the same function to float rounding: every batch norm
    folded into the convolution before it (with its running statistics, as in eval mode) and the
    weights in channels-last layout, which oneDNN's CPU convolutions run fastest (pass the raster
    as `channels_last` too). Planning at 50x50 on two CPU threads: 12 → 8 ms per call
    (experiments/README.md, "Speed"). Not for training: batch norm is gone."""
    from torch.nn.utils.fusion import fuse_conv_bn_eval

    fused = copy.deepcopy(model).eval()
    stem = fused.backbone
    stem[0], stem[1] = fuse_conv_bn_eval(stem[0], stem[1]), nn.Identity()
    for block in stem[4]:
        block.conv1, block.bn1 = fuse_conv_bn_eval(block.conv1, block.bn1), nn.Identity()
        block.conv2, block.bn2 = fuse_conv_bn_eval(block.conv2, block.bn2), nn.Identity()
        if block.downsample is not None:
            conv, bn = block.downsample
            block.downsample = nn.Sequential(fuse_conv_bn_eval(conv, bn))
    return fused.to(memory_format=torch.channels_last)


def with_raster_channels(state: dict, in_channels: int) -> dict:
    """A risk-map state dict whose first convolution takes `in_channels` raster channels: the
    trained kernels on the first channels, zeros on the added ones, so that the network computes
    exactly what it did while the added channels learn from zero."""
    weight = state["backbone.0.weight"]                         # [64, C, 7, 7]
    grown = weight.new_zeros((weight.shape[0], in_channels, *weight.shape[2:]))
    grown[:, : weight.shape[1]] = weight
    return {**state, "backbone.0.weight": grown}


def load_backbone_weights(model: RiskMapGenerator, path: str | Path) -> None:
    """Initialise the stem and layer1 from a local torchvision ResNet-34 state dict file.

    The RGB kernels of conv1 are averaged and repeated over the raster's channels.
    """
    path = Path(path)
    if not path.exists():
        raise InputError(f"--backbone-weights {path} does not exist; pass a local ResNet-34 "
                         "state dict (.pth or .safetensors)")
    try:
        if path.suffix == ".safetensors":
            from safetensors.torch import load_file

            state = load_file(str(path))
        else:
            state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001 - torch.load and safetensors raise many kinds
        reason = (str(err).splitlines() or [type(err).__name__])[0][:160]
        raise InputError(f"--backbone-weights {path} is not a readable state dict ({reason}); pass "
                         "a local torchvision ResNet-34 state dict (.pth or .safetensors)") from None
    if not isinstance(state, dict):
        raise InputError(f"--backbone-weights {path} holds a {type(state).__name__}, not a state "
                         "dict; pass a local torchvision ResNet-34 state dict")
    wanted = {"conv1.weight": "0.weight", "bn1.weight": "1.weight", "bn1.bias": "1.bias",
              "bn1.running_mean": "1.running_mean", "bn1.running_var": "1.running_var"}
    mapped = {}
    for key, value in state.items():
        if key in wanted:
            mapped[wanted[key]] = value
        elif key.startswith("layer1."):
            mapped["4." + key[len("layer1."):]] = value
    if "0.weight" not in mapped:
        raise InputError(f"--backbone-weights {path} holds no ResNet conv1.weight")
    rgb = mapped["0.weight"]
    mapped["0.weight"] = rgb.mean(dim=1, keepdim=True).repeat(1, model.config.in_channels, 1, 1)
    missing, _ = model.backbone.load_state_dict(mapped, strict=False)
    if any(not k.endswith("num_batches_tracked") for k in missing):
        raise InputError(f"--backbone-weights {path} lacks {missing[:3]}...; expected ResNet-34")


def load_model(path: Path, device: str = "cpu") -> tuple[RiskMapGenerator, dict]:
    """The trained generator (eval mode) and its sidecar; a space-time checkpoint is an
    InputError naming it (`riskmap.planner.st_model.load_spacetime_model` loads those)."""
    data = read_sidecar(path)
    if data.get("planner") == "spacetime":
        raise InputError(f"checkpoint {path} is a space-time planner; this needs a spatial risk-map "
                         "checkpoint (`riskmap train` without --planner spacetime)")
    model = load_weights(RiskMapGenerator(sidecar_section(data, "model", path, ModelConfig)), path,
                         "it was made by an incompatible version")
    model.to(device)
    sidecar_section(data, "raster", path, lambda **d: RasterConfig.from_dict(d))  # validates
    return model, data

