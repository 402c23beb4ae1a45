"""The one parallel runner (riskmap.infra.parallel): same results inline and in a process pool."""

import pytest

from rasterize.errors import InputError
from riskmap.infra.parallel import run_parallel


def square(x: int) -> int:
    return x * x


def test_inline_and_pool_give_the_same_pairs():
    inline = dict(run_parallel(square, range(6), workers=1))
    pooled = dict(run_parallel(square, range(6), workers=2))
    assert inline == pooled == {x: x * x for x in range(6)}


def test_bad_backend_and_workers_are_input_errors():
    with pytest.raises(InputError, match="--backend 'slurm' is unknown"):
        run_parallel(square, [1], backend="slurm")
    with pytest.raises(InputError, match="--workers 0"):
        run_parallel(square, [1], workers=0)
