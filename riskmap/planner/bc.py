"""Behaviour-cloning baselines of the planner paper's Table I: CNN, CNN-LSTM and RvS-G.

All three share the risk-map generator's raster backbone (ResNet-34 stem + layer1, built by
`riskmap.planner.model`) and regress the 12 future waypoints directly:

    cnn       raster [B, C, H, W]                 ─ backbone ─ pool ─ MLP (+ speed) ─► [B, 12, 2]
              (the head's output is added to the constant-velocity rollout at the ego's speed)
    cnn_lstm  rasters of the last K frames [B, K, C, H, W], each through the backbone and MLP,
              an LSTM over the K frame features ─ last hidden state ─► [B, 12, 2]
    rvsg      raster plus the goal map as one more channel [B, C + 1, H, W] ─ as cnn ─► [B, 12, 2]

RvS-G's goal is the route rule's goal cell, exactly the goal the risk-map planner gets, drawn as
the same Gaussian goal map upsampled from the grid to the raster. Waypoints are in the ego frame
(metres, x forward, y left) at 0.5 s steps, like every `Plan`.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import cv2
import numpy as np
import torch
from torch import nn

from rasterize.config import GridConfig, RasterConfig
from rasterize.errors import InputError
from rasterize.maps import goal_map, route_goal_cell
from rasterize.raster import rasterize_scene
from rasterize.scene import Scene
from riskmap.infra.checkpoint import route_settings_of
from riskmap.planner.model import SPEED_SCALE_MPS, ModelConfig, RiskMapGenerator
from riskmap.sim.loop.plan import PLAN_DT_S, PLAN_STEPS, Plan

BC_KINDS = ("cnn", "cnn_lstm", "rvsg")
CHECKPOINT_KIND = "bc"
WAYPOINT_SCALE_M = 10.0   # the head predicts waypoints in units of 10 m: outputs of order 1


def normalise_kind(kind: str) -> str:
    """`cnn-lstm` and `cnn_lstm` name the same baseline."""
    kind = kind.replace("-", "_")
    if kind not in BC_KINDS:
        raise InputError(f"baseline kind {kind!r} is unknown; use one of cnn, cnn_lstm, rvsg")
    return kind


@dataclass(frozen=True)
class BCConfig:
    """One baseline network. Goal variance in grid cells² (as the risk-map planner's)."""

    kind: str
    in_channels: int = 8            # raster channels (rvsg adds the goal channel on top)
    history_frames: int = 4         # cnn_lstm: frames 0.5 s apart, the newest is now
    feature_dim: int = 128          # per-frame feature after the MLP
    goal_resolution: int = 50       # rvsg: grid on which the goal map is drawn
    goal_variance: float = 5.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "kind", normalise_kind(self.kind))
        if self.history_frames < 1:
            raise InputError(f"history_frames must be >= 1, got {self.history_frames}")

    @property
    def frames(self) -> int:
        return self.history_frames if self.kind == "cnn_lstm" else 1

    @property
    def channels(self) -> int:
        return self.in_channels + (1 if self.kind == "rvsg" else 0)

    def to_dict(self) -> dict:
        return asdict(self)


def raster_backbone(in_channels: int) -> nn.Sequential:
    """The risk-map generator's ResNet-34 stem + layer1 for `in_channels` inputs: [B, 64, H/4, W/4]."""
    return RiskMapGenerator(ModelConfig(in_channels=in_channels)).backbone


class BCNet(nn.Module):
    """frames [B, K, C, H, W] in [0, 1], speed [B, K] (m/s) → waypoints [B, 12, 2] (ego frame, m)."""

    def __init__(self, config: BCConfig):
        super().__init__()
        self.config = config
        self.backbone = raster_backbone(config.channels)
        self.reduce = nn.Sequential(
            nn.Conv2d(64, 32, kernel_size=3, stride=2, padding=1), nn.ReLU(inplace=True),
            nn.AdaptiveAvgPool2d(4), nn.Flatten(),
        )
        self.frame_mlp = nn.Sequential(nn.Linear(32 * 16 + 1, config.feature_dim), nn.ReLU(inplace=True))
        self.lstm = (nn.LSTM(config.feature_dim, config.feature_dim, batch_first=True)
                     if config.kind == "cnn_lstm" else None)
        self.head = nn.Linear(config.feature_dim, PLAN_STEPS * 2)

    def forward(self, frames: torch.Tensor, speed: torch.Tensor) -> torch.Tensor:
        b, k = frames.shape[:2]
        features = self.reduce(self.backbone(frames.flatten(0, 1)))
        features = self.frame_mlp(torch.cat([features, speed.reshape(b * k, 1) / SPEED_SCALE_MPS], 1))
        features = features.view(b, k, -1)
        if self.lstm is not None:
            features = self.lstm(features)[0]
        offset = self.head(features[:, -1]).view(b, PLAN_STEPS, 2) * WAYPOINT_SCALE_M
        # The head learns the departure from constant velocity (straight ahead at the present
        # speed), so that the few epochs a CPU affords start from a sensible plan.
        along = speed[:, -1:] * (PLAN_DT_S * torch.arange(1, PLAN_STEPS + 1, dtype=speed.dtype))
        return offset + torch.stack([along, torch.zeros_like(along)], dim=-1)


def _frame_scenes(scene: Scene, frames: int) -> list[Scene]:
    """The scene as seen at the last `frames` times, 0.5 s (one scene step) apart, oldest first.

    Times before the ego's first valid state repeat the oldest one that exists.
    """
    past = scene.past()
    now = past.current_index
    ego_valid = past.valid[past.ego_index]
    out = []
    for back in range(frames - 1, -1, -1):
        k = now - back
        while k < now and (k < 0 or not ego_valid[k]):
            k += 1
        out.append(replace(past, states=past.states[:, :k + 1], valid=past.valid[:, :k + 1],
                           current_index=k))
    return out


def goal_channel(scene: Scene, raster: RasterConfig, grid: GridConfig, variance: float) -> np.ndarray:
    """The route goal as a Gaussian map on the grid, resized to the raster: float32 [H, W] in [0, 1]."""
    g = goal_map(route_goal_cell(scene, grid), grid, variance)
    return cv2.resize(g, (raster.cols, raster.rows), interpolation=cv2.INTER_LINEAR)


def bc_inputs(scene: Scene, config: BCConfig, raster: RasterConfig) -> tuple[np.ndarray, np.ndarray]:
    """(frames float32 [K, C', H, W] in [0, 1], speeds float32 [K] m/s) for one scene.

    Uses only the scene's past; the goal channel (rvsg) comes from the present route.
    """
    frames, speeds = [], []
    for frame in _frame_scenes(scene, config.frames):
        frames.append(rasterize_scene(frame, raster).astype(np.float32) / 255.0)
        speeds.append(float(frame.ego_state()[4]))
    stacked = np.stack(frames)
    if config.kind == "rvsg":
        grid = raster.grid(config.goal_resolution)
        goal = goal_channel(scene.past(), raster, grid, config.goal_variance)
        stacked = np.concatenate([stacked, goal[None, None]], axis=1)
    return stacked, np.asarray(speeds, dtype=np.float32)


def load_bc(path: str | Path) -> tuple[BCNet, dict]:
    """A trained baseline network (eval mode) and its sidecar."""
    from riskmap.infra.checkpoint import load_weights, read_sidecar, require_sections, sidecar_section

    side = read_sidecar(Path(path), kind=CHECKPOINT_KIND)
    require_sections(side, path, {"raster": ()})          # read by BCPlanner.load
    model = load_weights(BCNet(sidecar_section(side, "bc", path, BCConfig)), Path(path),
                         "train it again with `riskmap train-baseline`")
    return model, side


class BCPlanner:
    """`cnn:PATH`, `cnn_lstm:PATH`, `rvsg:PATH`: a trained baseline network behind the Planner protocol."""

    def __init__(self, model: BCNet, raster: RasterConfig, route_settings: dict | None = None):
        self.model, self.raster = model.eval(), raster
        self.config = model.config
        self.route_settings = route_settings    # route rule of recorded training data, if any

    @classmethod
    def load(cls, checkpoint: str | Path, expected_kind: str | None = None) -> BCPlanner:
        model, side = load_bc(checkpoint)
        if expected_kind is not None and model.config.kind != normalise_kind(expected_kind):
            raise InputError(f"checkpoint {checkpoint} holds a {model.config.kind} baseline, not "
                             f"{normalise_kind(expected_kind)}; use the matching SPEC prefix")
        return cls(model, RasterConfig.from_dict(side["raster"]), route_settings_of(side))

    def reset(self, scene: Scene) -> None:
        pass

    def plan(self, scene: Scene) -> Plan:
        t0 = time.perf_counter()
        frames, speeds = bc_inputs(scene, self.config, self.raster)
        t1 = time.perf_counter()
        with torch.no_grad():
            waypoints = self.model(torch.from_numpy(frames)[None], torch.from_numpy(speeds)[None])[0]
        t2 = time.perf_counter()
        return Plan(waypoints.double().numpy(),
                    timings_s={"raster": t1 - t0, "network": t2 - t1, "total": t2 - t0})
