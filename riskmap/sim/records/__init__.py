"""What a drive leaves: the record, the metrics, the failures that count (see `riskmap.sim`)."""
