"""Closed-loop simulation, in four layers (each imports only those below it; import-linter checks):

    loop/      the contract and the one loop: `Plan`/`Planner` (plan.py), their checks
               (plan_checks.py), the `World` protocol (world.py), tracking a plan (control.py)
               and `drive_world`, the rollout every command drives through (rollout.py)
    worlds/    what the ego is driven in: a highway-env episode (episode.py, on the faster road of
               fast_road/), traffic replaying a recorded episode (log_replay.py) and a CommonRoad
               recording (commonroad_replay.py)
    drivers/   who drives, besides the planner under test: the IDM law (idm.py), IDM/MOBIL on
               recorded lanes (recorded_idm.py), reactive recorded traffic (reactive_traffic.py),
               the yielding teacher (yielding.py), the scripted aggressive neighbour
               (aggressive.py) and parked vehicles (static_agents.py)
    records/   what a drive leaves: the one episode record (record.py), every metric
               (metrics.py), failures that count (failures.py, alternatives.py) and yielding
               events (yield_events.py)
"""
