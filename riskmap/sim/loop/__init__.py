"""The closed-loop contract and the one loop (see `riskmap.sim`)."""
