"""The neuro-symbolic guard: a TGAT accident predictor (System 1) raises an alert belief, and
AgentSpeak deceleration plans (System 2) decide whether to slow the ego down.

Modules: `events` (minimum projected separation d_s), `aggressors` (scripted aggressive
neighbours), `dataset` (accident windows), `tgat` (the predictor), `system2` (the BDI agent),
`guarded` (the planner wrapper), `cli` (the `riskmap guard` commands).
"""
