"""The worlds the ego is driven in (see `riskmap.sim`)."""
