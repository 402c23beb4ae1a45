"""Every name `riskmap` exports lazily resolves (a name pointing at the wrong module raised
AttributeError on first use)."""

import pytest

import riskmap


@pytest.mark.parametrize("name", riskmap.__all__)
def test_every_public_name_resolves(name):
    assert getattr(riskmap, name) is not None


def test_an_unknown_name_is_an_attribute_error():
    with pytest.raises(AttributeError):
        riskmap.NoSuchThing  # noqa: B018
