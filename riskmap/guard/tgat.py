"""TGAT accident predictor over one (ego u, neighbour i) interaction window.

The window is a two-node temporal graph: the observed events e_j = (u, i, t_j, r_j), j = 1..6,
with r_j the edge feature (d_s and the relative position and velocity), and the query time t_*
= t_6 + horizon of the virtual target event (edge feature zero). Layer l embeds node x at time τ by temporal multi-head attention:

    query  = W_q [h_x^{l−1}(τ) ‖ 0 ‖ Φ(0)]
    keys   = W_k [h_y^{l−1}(t_j) ‖ r_j ‖ Φ(τ − t_j)]   over the events with t_j < τ (y the partner)
    h_x^l(τ) = FFN([h_x^{l−1}(τ) ‖ attention output])

with the time encoding Φ(Δt) = (1/√m)[cos(ω_1Δt) … cos(ω_mΔt), sin(ω_1Δt) … sin(ω_mΔt)], ω
learned. h^0 is the projected static node feature. Two layers; the link score of (u, i) at
t_* is an MLP of [h_u^2(t_*) ‖ h_i^2(t_*)] with two outputs: a logit (σ gives the accident
probability) and the time to contact (softplus, seconds after the last observed event; trained on
the positive windows only, it is meaningful where the logit is high).

Shapes: node_u, node_i [B, NODE_DIM]; edge [B, 6, EDGE_DIM]; mask [B, 6] (True = event exists);
logits [B], ttc_s [B].
"""

from __future__ import annotations

import math

import torch
from torch import nn

from riskmap.guard.config import TGATConfig
from riskmap.guard.features import EDGE_DIM, EVENT_TIMES_S, NODE_DIM, OBSERVED, target_time_s


class TimeEncoding(nn.Module):
    """Φ(Δt) = (1/√m)[cos ωΔt, sin ωΔt] with learned frequencies ω [m] (rad/s)."""

    def __init__(self, m: int):
        super().__init__()
        # Initial frequencies spread over the periods that matter here (0.5 s .. 30 s).
        self.omega = nn.Parameter(2 * math.pi / torch.logspace(math.log10(0.5), math.log10(30.0), m))
        self.m = m

    def forward(self, dt: torch.Tensor) -> torch.Tensor:
        """dt [...] seconds → [..., 2m]."""
        phase = dt[..., None] * self.omega
        return torch.cat([torch.cos(phase), torch.sin(phase)], dim=-1) / math.sqrt(self.m)


class TemporalAttentionLayer(nn.Module):
    def __init__(self, hidden: int, time_dim: int, heads: int, dropout: float, edge_dim: int = EDGE_DIM):
        super().__init__()
        self.edge_dim = edge_dim
        query_dim = hidden + edge_dim + 2 * time_dim
        self.attention = nn.MultiheadAttention(hidden, heads, dropout=dropout, batch_first=True,
                                               kdim=query_dim, vdim=query_dim)
        self.query = nn.Linear(query_dim, hidden)
        self.merge = nn.Sequential(nn.Linear(2 * hidden, hidden), nn.ReLU(), nn.Dropout(dropout),
                                   nn.Linear(hidden, hidden))

    def forward(self, h_self: torch.Tensor, h_partner_at_events: torch.Tensor, edge: torch.Tensor,
                phi_query_zero: torch.Tensor, phi_keys: torch.Tensor, key_mask: torch.Tensor) -> torch.Tensor:
        """h_self [B, Q, H] at the Q query times; h_partner_at_events [B, 6, H]; edge [B, 6, E];
        phi_query_zero [2m]; phi_keys [B, Q, 6, 2m] = Φ(τ_q − t_j); key_mask [B, Q, 6] True = usable.
        Returns [B, Q, H]."""
        b, q, h = h_self.shape
        zero_edge = h_self.new_zeros(b, q, self.edge_dim)
        query = self.query(torch.cat([h_self, zero_edge, phi_query_zero.expand(b, q, -1)], -1))
        keys = torch.cat([h_partner_at_events[:, None].expand(b, q, -1, -1),
                          edge[:, None].expand(b, q, -1, -1), phi_keys], -1)       # [B, Q, 6, K]
        keys = keys.reshape(b * q, OBSERVED, -1)
        usable = key_mask.reshape(b * q, OBSERVED)
        empty = ~usable.any(-1)
        # A query with no earlier event attends to nothing: give it one dummy key, zero its output.
        safe_mask = usable.clone()
        safe_mask[empty, 0] = True
        out, _ = self.attention(query.reshape(b * q, 1, h), keys, keys, key_padding_mask=~safe_mask,
                                need_weights=False)
        out = out.reshape(b, q, h) * (~empty).reshape(b, q, 1)
        return self.merge(torch.cat([h_self, out], -1))


class TGAT(nn.Module):
    def __init__(self, config: TGATConfig = TGATConfig()):
        super().__init__()
        self.config = config
        self.node = nn.Linear(NODE_DIM, config.hidden)
        self.time = TimeEncoding(config.time_dim)
        edge_dim = EDGE_DIM + (2 if config.closest_approach else 0)
        self.layers = nn.ModuleList(TemporalAttentionLayer(config.hidden, config.time_dim, config.heads,
                                                           config.dropout, edge_dim) for _ in range(config.layers))
        self.score = nn.Sequential(nn.Linear(2 * config.hidden, config.hidden), nn.ReLU(),
                                   nn.Linear(config.hidden, 2))
        # Query times: the 6 event times then the target time.
        times = torch.tensor(list(EVENT_TIMES_S) + [target_time_s(config.horizon_s)], dtype=torch.float32)
        self.register_buffer("query_times", times, persistent=False)
        self.register_buffer("event_times", times[:OBSERVED].clone(), persistent=False)
        scale = [config.ds_scale_m] + [config.position_scale_m] * 2 + [config.speed_scale_mps] * 2
        self.register_buffer("edge_scale", torch.tensor(scale[:EDGE_DIM], dtype=torch.float32), persistent=False)

    def _normalise(self, node: torch.Tensor) -> torch.Tensor:
        scale = torch.ones(node.shape[-1], device=node.device)
        scale[2] = self.config.speed_scale_mps
        return node / scale

    def _closest_approach(self, edge: torch.Tensor) -> torch.Tensor:
        """[B, 6, 2]: at each event, the constant-velocity closest approach of the two centres
        within the horizon — its distance (÷ position scale, clipped at 5) and its time (÷ horizon).
        A crossing conflict shows here long before d_s shrinks."""
        dp, dv = edge[..., 1:3], edge[..., 3:5]
        horizon = self.config.horizon_s
        t_star = torch.clamp(-(dp * dv).sum(-1) / ((dv * dv).sum(-1) + 1e-6), 0.0, horizon)
        d_star = torch.linalg.vector_norm(dp + dv * t_star[..., None], dim=-1)
        return torch.stack([torch.clamp(d_star / self.config.position_scale_m, 0.0, 5.0), t_star / horizon], -1)

    def forward(self, node_u: torch.Tensor, node_i: torch.Tensor, edge: torch.Tensor,
                mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(logits [B], time to contact [B] in seconds)."""
        b = node_u.shape[0]
        q = self.query_times.numel()
        derived = self._closest_approach(edge) if self.config.closest_approach else None
        edge = torch.clamp(edge / self.edge_scale, -5.0, 5.0)
        if derived is not None:
            edge = torch.cat([edge, derived], -1)
        edge = edge * mask[..., None]
        dt = self.query_times[:, None] - self.event_times[None, :]                  # [Q, 6]
        earlier = (dt > 0)[None] & mask[:, None, :]                                  # [B, Q, 6]
        phi_keys = self.time(dt.clamp(min=0.0))[None].expand(b, -1, -1, -1)
        phi_zero = self.time(torch.zeros((), device=edge.device))
        h_u = self.node(self._normalise(node_u))[:, None].expand(b, q, -1)           # h^0, static
        h_i = self.node(self._normalise(node_i))[:, None].expand(b, q, -1)
        for layer in self.layers:
            # The partner's embedding at each event time comes from the previous layer.
            new_u = layer(h_u, h_i[:, :OBSERVED], edge, phi_zero, phi_keys, earlier)
            new_i = layer(h_i, h_u[:, :OBSERVED], edge, phi_zero, phi_keys, earlier)
            h_u, h_i = new_u, new_i
        out = self.score(torch.cat([h_u[:, -1], h_i[:, -1]], -1))
        return out[:, 0], nn.functional.softplus(out[:, 1])
