"""The space-time planner's network, IRL step and sampler (DESIGN §3b)."""

import numpy as np
import pytest
import torch

from rasterize.config import Extent, GridConfig
from rasterize.errors import InputError
from riskmap.planner.model import ModelConfig, RiskMapGenerator
from riskmap.planner.st_irl import SpaceTimeIRLConfig, demo_one_hot, demo_step_nll, st_irl_step
from riskmap.planner.st_model import SpaceTimeConfig, SpaceTimeRiskMapGenerator, state_from_spatial
from riskmap.planner.st_sampler import sample_spacetime_paths, spacetime_plan, to_plan_steps
from riskmap.planner.st_vi import spacetime_actions, spacetime_value_iteration, spacetime_visitation

GRID = GridConfig(Extent(10.0, 10.0, 10.0, 10.0), rows=20, cols=20)     # 1 m cells, ego (10, 10)


@pytest.mark.parametrize("bad", [dict(steps=5), dict(steps=0), dict(max_forward=0),
                                 dict(max_forward=17), dict(max_across=-1), dict(max_across=9)])
def test_out_of_range_steps_and_reach_are_input_errors(bad):
    with pytest.raises(InputError):
        SpaceTimeConfig(**bad)


def test_started_from_a_spatial_network_it_gives_that_risk_map_at_every_step():
    torch.manual_seed(0)
    config = ModelConfig(in_channels=8, resolution=12)
    spatial = RiskMapGenerator(config).eval()
    st = SpaceTimeRiskMapGenerator(config, SpaceTimeConfig(steps=4)).eval()
    st.load_state_dict(state_from_spatial(st, spatial.state_dict()))
    raster, motion = torch.rand(2, 8, 48, 48), torch.rand(2, 3, 12, 12)
    evidence, route = torch.rand(2, 4, 2, 12, 12), torch.rand(2, 12, 12)
    with torch.no_grad():
        r, g = st(raster, motion, evidence, route)
        risk = spatial(raster, motion)
    assert r.shape == (2, 4, 12, 12) and (r <= 0).all()
    for t in range(4):
        torch.testing.assert_close(r[:, t], risk, rtol=1e-5, atol=1e-5)
    # the goal starts as logsigmoid(20 · route goal − 10): 0 on the route's goal, −10 far away
    torch.testing.assert_close(g, torch.nn.functional.logsigmoid(20 * route - 10))
    with pytest.raises(InputError, match="evidence"):
        st(raster, motion, evidence[:, :3], route)


def test_the_irl_gradient_is_the_contracts():
    """∂loss/∂r_t = −(D_demo_t − D_t − v D_t ⊙ N_t) / B, none at steps the human is off the grid,
    and ∂loss/∂g = −(D_demo_T − D_T) / B."""
    torch.manual_seed(1)
    st = SpaceTimeConfig(steps=3, max_forward=2, max_across=1)
    reward = (-torch.rand(2, 3, 6, 5, dtype=torch.float64)).requires_grad_()
    batch = {"goal_cell": torch.tensor([[0, 2], [1, 1]]), "start_cell": torch.tensor([[5, 2], [4, 3]]),
             "st_demo": torch.tensor([[[4, 2], [3, 2], [1, 2]], [[3, 3], [-1, -1], [1, 2]]]),
             "st_uncertainty": torch.rand(2, 3, 6, 5, dtype=torch.float64)}
    config = SpaceTimeIRLConfig(st, uncertainty_weight=0.7, goal_variance=2.0)
    from riskmap.planner.irl import goal_log_map

    g = goal_log_map(batch["goal_cell"], 6, 5, 2.0, torch.float64).requires_grad_()
    step = st_irl_step(reward, g, batch, config)
    step.loss.backward()
    _, policy = spacetime_value_iteration(reward.detach(), g.detach(), 2, 1)
    visits = spacetime_visitation(policy, batch["start_cell"], 2, 1)
    demo = demo_one_hot(batch["st_demo"], 6, 5, torch.float64)
    expected = -(demo - visits - 0.7 * visits * batch["st_uncertainty"]) / 2
    expected[1, 1] = 0.0                                     # the human off the grid at step 2
    torch.testing.assert_close(reward.grad, expected)
    torch.testing.assert_close(g.grad, -(demo[:, -1] - visits[:, -1]) / 2)
    assert demo[1, 1].sum() == 0 and demo[0, 2, 1, 2] == 1
    nll = demo_step_nll(visits, batch["st_demo"])
    assert nll.shape == (2,) and (nll > 0).all()


def test_a_larger_uncertainty_weight_keeps_the_policy_off_where_others_will_be():
    """Descending the loss with v > 0 lowers r_t where the policy meets N_t, more for larger v."""
    st = SpaceTimeConfig(steps=3, max_forward=1, max_across=1)
    base = torch.full((1, 3, 5, 3), -1.0, dtype=torch.float64)
    unc = torch.zeros(1, 3, 5, 3, dtype=torch.float64)
    unc[0, 1, 3, 1] = 1.0                                   # another agent at (3, 1) at step 2
    batch = {"goal_cell": torch.tensor([[1, 1]]), "start_cell": torch.tensor([[4, 1]]),
             "st_demo": torch.tensor([[[4, 1], [3, 1], [2, 1]]]), "st_uncertainty": unc}
    drops = []
    for v in (0.0, 1.0, 5.0):
        reward = base.clone().requires_grad_()
        goal = torch.zeros(1, 5, 3, dtype=torch.float64)
        st_irl_step(reward, goal, batch, SpaceTimeIRLConfig(st, v, 1.0)).loss.backward()
        drops.append(float(reward.grad[0, 1, 3, 1]))
    assert drops[0] < drops[1] < drops[2]


def test_sampled_paths_follow_the_policy_and_stay_on_the_grid():
    steps, (k, lat) = 4, (2, 1)
    actions = spacetime_actions(k, lat)
    policy = torch.zeros(steps, len(actions), 20, 20, dtype=torch.float64)
    forward_two = [i for i, a in enumerate(actions) if tuple(a) == (-2, 0)][0]
    policy[:, forward_two] = 1.0                           # always 2 rows forward
    flat = sample_spacetime_paths(policy, (10, 10), k, lat, 50, torch.Generator().manual_seed(0))
    np.testing.assert_array_equal(flat[0], [210, 170, 130, 90, 50])
    waypoints, members = spacetime_plan(policy, (10, 10), GRID, k, lat, seed=0)
    # 2 m per 1.5 s step (T = 4 over 6 s), interpolated to 0.5 s: 2/3 m per waypoint
    np.testing.assert_allclose(waypoints[:, 0], np.arange(1, 13) * 2 / 3)
    np.testing.assert_allclose(waypoints[:, 1], 0.0)
    # a policy that spreads its mass samples every action, never one off the grid
    value, policy = spacetime_value_iteration(torch.zeros(1, 4, 3, 3, dtype=torch.float64),
                                              torch.zeros(1, 3, 3, dtype=torch.float64), 2, 1)
    flat = sample_spacetime_paths(policy[0], (2, 0), 2, 1, 2000, torch.Generator().manual_seed(1))
    rows, cols = np.divmod(flat, 3)
    assert (rows >= 0).all() and (cols >= 0).all() and (cols < 3).all()
    assert len(np.unique(flat[:, 1])) == 6          # from the corner: 2 columns x (stay, 1, 2 forward)


def test_a_waiting_policy_plans_to_stand():
    actions = spacetime_actions(2, 1)
    stay = [i for i, a in enumerate(actions) if tuple(a) == (0, 0)][0]
    policy = torch.zeros(12, len(actions), 20, 20)
    policy[:, stay] = 1.0
    waypoints, _ = spacetime_plan(policy, (10, 10), GRID, 2, 1, seed=3)
    np.testing.assert_array_equal(waypoints, np.zeros((12, 2)))


def test_the_plan_is_the_largest_clusters_mean_between_cell_centres():
    """Half the paths move 1 row a step, half 2 rows: one cluster each unless merged; with a
    single cluster the plan is their mean, 1.5 m a step, between the cells."""
    from riskmap.planner.st_sampler import SpaceTimeSamplerConfig

    actions = spacetime_actions(2, 0)
    policy = torch.zeros(12, len(actions), 20, 20, dtype=torch.float64)
    policy[0, 1], policy[0, 2] = 0.5, 0.5                       # first step: 1 or 2 forward
    policy[1:, 0] = 1.0                                          # then stand
    waypoints, _ = spacetime_plan(policy, (10, 10), GRID, 2, 0, SpaceTimeSamplerConfig(4000, 1))
    assert 1.45 < waypoints[0, 0] < 1.55 and np.allclose(waypoints[1:], waypoints[0])


def test_coarser_steps_are_interpolated_to_the_plans_twelve():
    points = np.array([[3.0, 0.0], [6.0, 1.0], [9.0, 1.0]])     # T = 3: 2 s apart
    plan = to_plan_steps(points)
    assert plan.shape == (12, 2)
    np.testing.assert_allclose(plan[3], [3.0, 0.0])
    np.testing.assert_allclose(plan[0], [0.75, 0.0])
    np.testing.assert_allclose(plan[-1], [9.0, 1.0])


def test_the_time_gap_prices_where_an_agent_was_up_to_the_gap_before():
    from riskmap.planner.st_planner import TimeGapConfig

    now = np.zeros((1, 6))
    now[0, 0] = 1.0
    predicted = np.zeros((4, 1, 6))
    for t in range(4):                    # an agent one cell further each 0.5 s step
        predicted[t, 0, t + 1] = 1.0
    penalty = TimeGapConfig(time_gap_s=1.0, weight=3.0).penalty(now, predicted, 0.5)
    # at step t: its cells at steps t − 2 … t (step 0: now), each priced 3
    np.testing.assert_array_equal(penalty[:, 0] > 0, [[1, 1, 0, 0, 0, 0], [1, 1, 1, 0, 0, 0],
                                                      [0, 1, 1, 1, 0, 0], [0, 0, 1, 1, 1, 0]])
    assert penalty.max() == 3.0
    np.testing.assert_array_equal(TimeGapConfig(0.0, 3.0).penalty(now, predicted, 0.5), 3 * predicted)
    with pytest.raises(InputError, match="time_gap"):
        TimeGapConfig(time_gap_s=-1.0, weight=1.0)


def test_the_reach_envelope_prices_exactly_the_cells_the_speed_cannot_reach():
    """ReachConfig against the kinematics written out: at step t the ego is between
    v0 t − ½ b t² (v0²/2b once stopped) and v0 t + ½ a t² ahead, give or take one row."""
    from rasterize.config import FAMILY_EXTENTS, GridConfig
    from rasterize.frames import cell_centres_ego
    from rasterize.maps import start_cell
    from riskmap.planner.st_planner import ReachConfig

    grid = GridConfig(FAMILY_EXTENTS["highway"], 50, 50)
    reach = ReachConfig(accel_mps2=2.0, decel_mps2=6.0, tolerance_cells=1.0, weight=7.0)
    row_m = grid.extent.length_m / grid.rows
    x = cell_centres_ego(grid)[..., 0] - cell_centres_ego(grid)[..., 0][start_cell(grid)]
    for v0 in (0.0, 5.0, 25.0):
        penalty = reach.penalty(v0, grid, 12, 0.5)
        assert penalty.shape == (12, 50, 50) and set(np.unique(penalty)) <= {0.0, 7.0}
        for k in range(12):
            t = 0.5 * (k + 1)
            hi = v0 * t + t * t
            lo = v0 * t - 3.0 * t * t if t < v0 / 6.0 else v0 * v0 / 12.0
            expected = ((x > hi + row_m) | (x < lo - row_m)) * 7.0
            np.testing.assert_array_equal(penalty[k], expected)
    assert not ReachConfig().penalty(5.0, grid, 12, 0.5).any()        # weight 0: off


def test_planning_maps_are_forwards_maps_against_a_float64_reference():
    """The planner's inference path (`planning_maps`, on the `for_inference` copy the planner
    runs, channels-last raster) computes forward's rewards and goal map: against forward in
    float64 of the same weights, to float32 rounding."""
    from riskmap.planner.model import for_inference

    torch.manual_seed(0)
    st = SpaceTimeRiskMapGenerator(ModelConfig(in_channels=8, resolution=12),
                                   SpaceTimeConfig(steps=4)).eval()
    with torch.no_grad():
        for parameter in st.head.parameters():       # a step part that is not zero, as trained
            parameter.uniform_(-0.5, 0.5)
    raster = (torch.rand(2, 8, 200, 200) > 0.7).float()
    motion, route = torch.rand(2, 3, 12, 12), torch.rand(2, 12, 12)
    evidence = torch.rand(2, 4, 2, 12, 12) * (torch.rand(2, 4, 2, 12, 12) > 0.6)
    with torch.no_grad():
        expected = st.double()(raster.double(), motion.double(), evidence.double(), route.double())
    fast = for_inference(st.float())
    reward, goal = fast.planning_maps(raster.contiguous(memory_format=torch.channels_last), motion,
                                      evidence, route)
    assert reward.dtype == goal.dtype == torch.float32
    assert reward.shape == (2, 4, 12, 12) and goal.shape == (2, 12, 12)
    torch.testing.assert_close(reward.double(), expected[0], rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(goal.double(), expected[1], rtol=1e-5, atol=1e-5)
    with pytest.raises(InputError):
        fast.planning_maps(raster, motion, evidence[:, :3], route)
