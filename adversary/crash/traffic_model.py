"""The learned traffic model: a scene CVAE in STRIVE's manner with CRASH's encoders.

    F_s = h_s(past)          MLP-Mixer over each agent's 5 past steps (its own frame at t0)
    F_m = h_m(lane chunks)   MLP-Mixer over the L lane chunks nearest each agent (its own frame)
    Z   = g(F_s, F_m)        one round of message passing over the fully connected scene graph
                             (edges carry the pose and velocity of j in i's frame)
    prior     p(z_i | Z)          = N(mu, sigma) from Z_i
    posterior q(z_i | Z, future)  = N(mu, sigma) from Z_i and a Mixer over i's own future
    decoder   autoregressive, one MLP per step (hidden 128 -> 64) on [z_i, Z_i, own speed and
              heading change, nearest lane point, two nearest agents] -> (acceleration, yaw rate)
              -> kinematic bicycle (dt 0.5 s, no reversing, speed <= max_speed_mps)

The ego is node 0 with its own latent like every agent. `decode(..., fixed=...)` overrides the
state of chosen agents at every step with given states (the black-box planner's ego), so that
the others react to what the ego really does. Shapes follow `adversary.crash.batch`; decoded
trajectories are [B, N, F, 4] (x, y, heading, speed) in the scene frame.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
from torch import nn

from adversary.crash.batch import Batch
from adversary.crash.features import FUTURE_STEPS, STEP_S


@dataclass(frozen=True)
class TrafficModelConfig:
    hidden: int = 64                 # D, every embedding
    latent: int = 32                 # per-agent latent size (STRIVE's)
    mixer_layers: int = 2
    position_scale_m: float = 10.0   # positions are divided by this before entering a network
    speed_scale_mps: float = 10.0
    max_accel_mps2: float = 8.0      # decoder outputs are squashed into these bounds
    max_yaw_rate_rps: float = 0.8
    max_speed_mps: float = 45.0
    neighbours: int = 2              # nearest agents the decoder sees at each step

    def to_dict(self) -> dict:
        return asdict(self)


def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.GELU())
    return nn.Sequential(*layers)


class MixerBlock(nn.Module):
    """One MLP-Mixer block on [..., T, C]: mix across the T tokens, then across the C channels."""

    def __init__(self, tokens: int, channels: int, expansion: int = 2):
        super().__init__()
        self.norm_tokens, self.norm_channels = nn.LayerNorm(channels), nn.LayerNorm(channels)
        self.tokens = _mlp([tokens, tokens * expansion, tokens])
        self.channels = _mlp([channels, channels * expansion, channels])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = x + self.tokens(self.norm_tokens(x).transpose(-1, -2)).transpose(-1, -2)
        return x + self.channels(self.norm_channels(x))


class MixerEncoder(nn.Module):
    """Tokens [..., T, F_in] with a validity mask [..., T] -> one embedding [..., D]."""

    def __init__(self, tokens: int, features: int, hidden: int, layers: int):
        super().__init__()
        self.embed = nn.Linear(features + 1, hidden)
        self.blocks = nn.Sequential(*[MixerBlock(tokens, hidden) for _ in range(layers)])
        self.norm = nn.LayerNorm(hidden)

    def forward(self, tokens: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
        v = valid.unsqueeze(-1).float()
        x = self.blocks(self.embed(torch.cat([tokens * v, v], dim=-1)))
        pooled = (x * v).sum(-2) / v.sum(-2).clamp(min=1.0)
        return self.norm(pooled)


def wrap(angle: torch.Tensor) -> torch.Tensor:
    return torch.atan2(torch.sin(angle), torch.cos(angle))


def into_frame(xy: torch.Tensor, origin: torch.Tensor, heading: torch.Tensor) -> torch.Tensor:
    """Points [..., 2] into frames (origin [..., 2], heading [...]) broadcast against them."""
    d = xy - origin
    c, s = torch.cos(heading), torch.sin(heading)
    return torch.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], dim=-1)


@dataclass
class Encoded:
    context: torch.Tensor        # Z [B, N, D]
    prior_mu: torch.Tensor       # [B, N, latent]
    prior_logvar: torch.Tensor
    start: torch.Tensor          # [B, N, 4] (x, y, heading, speed) at t0, scene frame


class TrafficModel(nn.Module):
    def __init__(self, config: TrafficModelConfig = TrafficModelConfig(), lane_chunks: int = 8,
                 chunk_points: int = 8):
        super().__init__()
        self.config = config
        d, k = config.hidden, config.latent
        self.lane_chunks, self.chunk_points = lane_chunks, chunk_points
        self.past_encoder = MixerEncoder(5, 5, d, config.mixer_layers)
        self.map_encoder = MixerEncoder(lane_chunks, chunk_points * 4, d, config.mixer_layers)
        self.future_encoder = MixerEncoder(FUTURE_STEPS, 5, d, config.mixer_layers)
        self.node = _mlp([2 * d + 3, d, d])
        self.message = _mlp([2 * d + 7, d, d])
        self.update = _mlp([2 * d, d, d])
        self.prior = _mlp([d, d, 2 * k])
        self.posterior = _mlp([2 * d, d, 2 * k])
        step_features = 4 + 4 + 5 * config.neighbours
        self.decoder = _mlp([k + d + step_features, 128, 64, 2])

    # ---- encoding ---------------------------------------------------------------------------

    def _own_frame(self, states: torch.Tensor, start: torch.Tensor) -> torch.Tensor:
        """States [B, N, T, 5] (scene frame) -> (x, y, cos, sin, speed) in each agent's t0 frame."""
        s = self.config
        xy = into_frame(states[..., :2], start[:, :, None, :2], start[:, :, None, 2])
        rel = torch.atan2(states[..., 3], states[..., 2]) - start[:, :, None, 2]
        return torch.cat([xy / s.position_scale_m, torch.cos(rel)[..., None], torch.sin(rel)[..., None],
                          states[..., 4:5] / s.speed_scale_mps], dim=-1)

    def _edges(self, start: torch.Tensor) -> torch.Tensor:
        """Edge features [B, N, N, 7]: agent j seen from agent i at t0."""
        s = self.config
        xy_i, xy_j = start[:, :, None, :2], start[:, None, :, :2]
        th_i, th_j = start[:, :, None, 2], start[:, None, :, 2]
        rel = into_frame(xy_j, xy_i, th_i)
        dth = th_j - th_i
        v_i = start[:, :, None, 3:4] * torch.stack([torch.cos(th_i), torch.sin(th_i)], -1)
        v_j = start[:, None, :, 3:4] * torch.stack([torch.cos(th_j), torch.sin(th_j)], -1)
        dv = into_frame(v_j - v_i + xy_i, xy_i, th_i)       # rotate only
        dist = rel.norm(dim=-1, keepdim=True)
        return torch.cat([rel / s.position_scale_m, torch.cos(dth)[..., None], torch.sin(dth)[..., None],
                          dv / s.speed_scale_mps, dist / s.position_scale_m], dim=-1)

    def encode(self, batch: Batch) -> Encoded:
        now = batch.past[:, :, -1]
        start = torch.stack([now[..., 0], now[..., 1], torch.atan2(now[..., 3], now[..., 2]), now[..., 4]], -1)
        past = self._own_frame(batch.past, start)
        f_s = self.past_encoder(past, batch.past_valid)
        b, n = batch.chunks.shape[:2]
        chunks = batch.chunks.reshape(b, n, self.lane_chunks, self.chunk_points * 4)
        chunks = chunks / torch.tensor([self.config.position_scale_m] * 2 + [1.0, 1.0]).repeat(
            self.chunk_points)
        f_m = self.map_encoder(chunks, batch.chunk_valid)
        sizes = batch.sizes / 5.0
        h0 = self.node(torch.cat([f_s, f_m, sizes, start[..., 3:4] / self.config.speed_scale_mps], -1))
        pair = batch.agent_mask[:, :, None] & batch.agent_mask[:, None, :]
        pair = pair & ~torch.eye(n, dtype=torch.bool, device=pair.device)
        msg = self.message(torch.cat([h0[:, :, None].expand(-1, -1, n, -1),
                                      h0[:, None, :].expand(-1, n, -1, -1), self._edges(start)], -1))
        w = pair.unsqueeze(-1).float()
        agg = (msg * w).sum(2) / w.sum(2).clamp(min=1.0)
        context = h0 + self.update(torch.cat([h0, agg], -1))
        mu, logvar = self.prior(context).chunk(2, dim=-1)
        return Encoded(context, mu, logvar.clamp(-8.0, 4.0), start)

    def posterior_of(self, batch: Batch, enc: Encoded) -> tuple[torch.Tensor, torch.Tensor]:
        """(mu, logvar) [B, N, latent] of q(z | past, future); needs batch.future."""
        future = self._own_frame(batch.future, enc.start)
        f_f = self.future_encoder(future, batch.future_valid)
        mu, logvar = self.posterior(torch.cat([enc.context, f_f], -1)).chunk(2, dim=-1)
        return mu, logvar.clamp(-8.0, 4.0)

    # ---- decoding ---------------------------------------------------------------------------

    def _step_features(self, batch: Batch, state: torch.Tensor, start: torch.Tensor, step: int
                       ) -> torch.Tensor:
        s = self.config
        xy, th, v = state[..., :2], state[..., 2], state[..., 3]
        own = torch.stack([v / s.speed_scale_mps, torch.cos(th - start[..., 2]),
                           torch.sin(th - start[..., 2]), torch.full_like(v, step / FUTURE_STEPS)], -1)
        # The nearest lane centre point, in the agent's frame now (index chosen without gradient).
        lanes = batch.lane_points
        d2 = ((xy[:, :, None, :] - lanes[:, None, :, :2]) ** 2).sum(-1)
        d2 = d2.masked_fill(~batch.lane_mask[:, None, :], float("inf"))
        idx = d2.argmin(-1)
        near = torch.gather(lanes, 1, idx[..., None].expand(-1, -1, 4))
        rel_xy = into_frame(near[..., :2], xy, th) / s.position_scale_m
        lane_th = torch.atan2(near[..., 3], near[..., 2]) - th
        lane = torch.cat([rel_xy.clamp(-3.0, 3.0), torch.cos(lane_th)[..., None],
                          torch.sin(lane_th)[..., None]], -1)
        # The nearest agents now, in the agent's frame.
        n = xy.shape[1]
        dist = torch.cdist(xy, xy)
        dist = dist.masked_fill(~batch.agent_mask[:, None, :], float("inf"))
        dist = dist + torch.diag(torch.full((n,), float("inf"), device=xy.device))
        k = min(s.neighbours, max(n - 1, 0))
        feats = []
        if k:
            order = dist.detach().topk(k, dim=-1, largest=False).indices          # [B, N, k]
            for j in range(k):
                other = torch.gather(state, 1, order[..., j:j + 1].expand(-1, -1, 4))
                exists = torch.gather(dist, 2, order[..., j:j + 1]).squeeze(-1).isfinite()
                rel = into_frame(other[..., :2], xy, th) / s.position_scale_m
                vel_o = other[..., 3:4] * torch.stack([torch.cos(other[..., 2]), torch.sin(other[..., 2])], -1)
                vel_m = v[..., None] * torch.stack([torch.cos(th), torch.sin(th)], -1)
                dv = into_frame(vel_o - vel_m + xy, xy, th) / s.speed_scale_mps
                e = exists.float()[..., None]
                feats.append(torch.cat([rel.clamp(-5.0, 5.0) * e, dv * e, e], -1))
        for _ in range(s.neighbours - k):
            feats.append(torch.zeros(xy.shape[:2] + (5,), device=xy.device))
        return torch.cat([own, lane] + feats, -1)

    def decode(self, batch: Batch, enc: Encoded, z: torch.Tensor, fixed: torch.Tensor | None = None,
               fixed_mask: torch.Tensor | None = None) -> torch.Tensor:
        """Trajectories [B, N, F, 4] from latents z [B, N, latent]. `fixed` [B, N, F, 4] with
        `fixed_mask` [B, N]: those agents take the given states instead of their decoded ones."""
        s = self.config
        state = enc.start
        out = []
        for t in range(FUTURE_STEPS):
            feats = self._step_features(batch, state, enc.start, t)
            control = torch.tanh(self.decoder(torch.cat([z, enc.context, feats], -1)))
            accel, yaw_rate = control[..., 0] * s.max_accel_mps2, control[..., 1] * s.max_yaw_rate_rps
            v0, th0 = state[..., 3], state[..., 2]
            v1 = (v0 + accel * STEP_S).clamp(0.0, s.max_speed_mps)     # no reversing
            th1 = th0 + yaw_rate * STEP_S
            mid_v, mid_th = 0.5 * (v0 + v1), th0 + 0.5 * yaw_rate * STEP_S
            xy1 = state[..., :2] + STEP_S * mid_v[..., None] * torch.stack(
                [torch.cos(mid_th), torch.sin(mid_th)], -1)
            state = torch.cat([xy1, th1[..., None], v1[..., None]], -1)
            if fixed is not None:
                state = torch.where(fixed_mask[..., None], fixed[:, :, t], state)
            out.append(state)
        return torch.stack(out, dim=2)


def kl_normal(mu_q, logvar_q, mu_p, logvar_p) -> torch.Tensor:
    """KL(N(mu_q, var_q) || N(mu_p, var_p)) summed over the last dimension."""
    return 0.5 * (logvar_p - logvar_q + (logvar_q.exp() + (mu_q - mu_p) ** 2) / logvar_p.exp() - 1.0).sum(-1)


def log_normal(z, mu, logvar) -> torch.Tensor:
    """log N(z; mu, var) summed over the last dimension."""
    return -0.5 * (logvar + (z - mu) ** 2 / logvar.exp() + math.log(2 * math.pi)).sum(-1)


def states_of(traj: torch.Tensor) -> torch.Tensor:
    """(x, y, heading, speed) [..., 4] as (x, y, cos, sin, speed) [..., 5]."""
    return torch.stack([traj[..., 0], traj[..., 1], torch.cos(traj[..., 2]), torch.sin(traj[..., 2]),
                        traj[..., 3]], -1)
