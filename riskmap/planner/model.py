"""The risk-map generator (planner paper §IV-A, P2T's layout).

    raster [B, C, 200, 200] ─ ResNet-34 stem + layer1 ─► [B, 64, 50, 50] ─ conv ─► resize to G×G
    ─ concat motion features [B, 3, G, G] ─ 1×1 convs 67→32→32→1 ─ LogSigmoid ─► risk [B, G, G]

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
from riskmap.infra.checkpoint import load_weights, read_sidecar


@dataclass(frozen=True)
class ModelConfig:
    in_channels: int = 8          # raster channels
    resolution: int = 50          # risk-map grid G (25, 50, 75, 100 ...)
    encoder_channels: int = 64    # after the extra conv
    head_channels: int = 32

    def to_dict(self) -> dict:
        return asdict(self)


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

    def forward(self, raster: torch.Tensor, motion: torch.Tensor) -> torch.Tensor:
        """raster [B, C, H, W], motion [B, 3, G, G] → risk map [B, G, G] (≤ 0)."""
        g = self.config.resolution
        features = self.encoder_conv(self.backbone(raster))
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
    """The trained generator (eval mode) and its sidecar."""
    data = read_sidecar(path)
    model = load_weights(RiskMapGenerator(ModelConfig(**data["model"])), path,
                         "it was made by an incompatible version")
    model.to(device)
    RasterConfig.from_dict(data["raster"])  # validates
    return model, data

