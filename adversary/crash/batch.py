"""`SceneTensors` of several scenes padded into one batch of torch tensors.

Shapes as in `adversary.crash.features`, with a batch dimension B in front and agents padded to
the batch's largest N (`agent_mask` [B, N] marks real agents), lane points padded to the largest
Q (`lane_mask` [B, Q]) and off-road fields padded (edge values) to the largest grid:

    field [B, 1, R, C] distances (m); field_origin [B, 2] (x0, y0); field_cell_m [B]
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import torch
import torch.nn.functional as F

from adversary.crash.features import SceneTensors


@dataclass
class Batch:
    past: torch.Tensor
    past_valid: torch.Tensor
    future: torch.Tensor
    future_valid: torch.Tensor
    sizes: torch.Tensor
    agent_mask: torch.Tensor
    chunks: torch.Tensor
    chunk_valid: torch.Tensor
    lane_points: torch.Tensor
    lane_mask: torch.Tensor
    field: torch.Tensor
    field_origin: torch.Tensor
    field_cell_m: torch.Tensor

    @property
    def size(self) -> int:
        return self.past.shape[0]

    def to(self, device) -> Batch:
        return Batch(**{f.name: getattr(self, f.name).to(device) for f in fields(self)})

    def repeat(self, times: int) -> Batch:
        """The batch repeated `times` along B (scene 0 x times, scene 1 x times, ...)."""
        return Batch(**{f.name: getattr(self, f.name).repeat_interleave(times, dim=0)
                        for f in fields(self)})


def collate(items: list[SceneTensors]) -> Batch:
    b = len(items)
    n = max(it.num_agents for it in items)
    q = max(len(it.lane_points) for it in items)
    rows = max(it.off_road.distance.shape[0] for it in items)
    cols = max(it.off_road.distance.shape[1] for it in items)

    def pad_agents(name, dtype):
        first = getattr(items[0], name)
        out = np.zeros((b, n) + first.shape[1:], dtype)
        for i, it in enumerate(items):
            arr = getattr(it, name)
            out[i, : len(arr)] = arr
        return torch.from_numpy(out)

    agent_mask = np.zeros((b, n), bool)
    lane_points = np.zeros((b, q, 4), np.float32)
    lane_mask = np.zeros((b, q), bool)
    field = np.zeros((b, 1, rows, cols), np.float32)
    for i, it in enumerate(items):
        agent_mask[i, : it.num_agents] = True
        lane_points[i, : len(it.lane_points)] = it.lane_points
        lane_mask[i, : len(it.lane_points)] = True
        d = it.off_road.distance
        field[i, 0] = np.pad(d, ((0, rows - d.shape[0]), (0, cols - d.shape[1])), mode="edge")
    return Batch(
        past=pad_agents("past", np.float32), past_valid=pad_agents("past_valid", bool),
        future=pad_agents("future", np.float32), future_valid=pad_agents("future_valid", bool),
        sizes=pad_agents("sizes", np.float32), agent_mask=torch.from_numpy(agent_mask),
        chunks=pad_agents("chunks", np.float32), chunk_valid=pad_agents("chunk_valid", bool),
        lane_points=torch.from_numpy(lane_points), lane_mask=torch.from_numpy(lane_mask),
        field=torch.from_numpy(field),
        field_origin=torch.tensor([[it.off_road.x0, it.off_road.y0] for it in items], dtype=torch.float32),
        field_cell_m=torch.tensor([it.off_road.cell_m for it in items], dtype=torch.float32),
    )


def sample_field(batch: Batch, xy: torch.Tensor) -> torch.Tensor:
    """Bilinear off-road distances (m) at scene-frame points xy [B, ..., 2] -> [B, ...]."""
    b = xy.shape[0]
    rows, cols = batch.field.shape[-2:]
    u = (xy - batch.field_origin.view(b, *([1] * (xy.dim() - 2)), 2)) / batch.field_cell_m.view(
        b, *([1] * (xy.dim() - 1)))
    # grid_sample's normalised coordinates (align_corners=False): cell c spans [c, c + 1).
    norm = torch.stack([u[..., 0] / cols * 2 - 1, u[..., 1] / rows * 2 - 1], dim=-1)
    flat = norm.reshape(b, 1, -1, 2)
    out = F.grid_sample(batch.field, flat, mode="bilinear", padding_mode="border", align_corners=False)
    return out.reshape(xy.shape[:-1])
