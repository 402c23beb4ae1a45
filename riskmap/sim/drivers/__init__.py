"""The drivers of the traffic around the ego, and the rule-based egos (see `riskmap.sim`)."""
