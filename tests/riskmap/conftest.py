import pytest

from riskmap.data.collect import CollectConfig, collect
from riskmap.training.train import TrainConfig, train


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """Three short intersection episodes."""
    d = tmp_path_factory.mktemp("tiny") / "intersection"
    collect(CollectConfig("intersection-v0", episodes=3, seed=11), d, progress=False)
    return d


def tiny_train_config(data, out, **kw) -> TrainConfig:
    settings = dict(data=str(data), out=str(out), resolution=25, epochs=2, batch_size=4,
                    max_windows=8, val_ade_windows=2, lr=1e-3, seed=0)
    settings.update(kw)
    return TrainConfig(**settings)


@pytest.fixture(scope="session")
def tiny_checkpoint(tiny_dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("run") / "tiny"
    train(tiny_train_config(tiny_dataset, out), progress=False)
    return out / "best"
