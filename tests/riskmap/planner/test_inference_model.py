"""The planning copy of the risk-map generator (`for_inference`) computes the same function."""

import torch

from riskmap.planner.model import ModelConfig, RiskMapGenerator, for_inference


def _model_with_trained_like_statistics(resolution: int, channels: int = 8) -> RiskMapGenerator:
    torch.manual_seed(0)
    model = RiskMapGenerator(ModelConfig(in_channels=channels, resolution=resolution))
    for module in model.modules():          # batch norms as after training, not the identity
        if isinstance(module, torch.nn.BatchNorm2d):
            module.running_mean.uniform_(-0.5, 0.5)
            module.running_var.uniform_(0.5, 2.0)
            module.weight.data.uniform_(0.5, 1.5)
            module.bias.data.uniform_(-0.2, 0.2)
    return model.eval()


def test_folded_channels_last_copy_equals_the_model_in_eval_mode():
    for resolution, channels in ((50, 8), (25, 10)):
        model = _model_with_trained_like_statistics(resolution, channels)
        fast = for_inference(model)
        raster = (torch.rand(2, channels, 200, 200) > 0.7).float()
        motion = torch.rand(2, 3, resolution, resolution)
        with torch.no_grad():
            expected = model(raster, motion)
            got = fast(raster.contiguous(memory_format=torch.channels_last), motion)
            plain_layout = fast(raster, motion)
        torch.testing.assert_close(got, expected, rtol=1e-5, atol=1e-4)
        torch.testing.assert_close(plain_layout, expected, rtol=1e-5, atol=1e-4)
        assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in fast.modules())
        # The original keeps its batch norms (training goes on with it).
        assert any(isinstance(m, torch.nn.BatchNorm2d) for m in model.modules())
