"""``window_misfit``: whether ``cfar_2d``'s window fits a map, asked before running it."""

import numpy as np
import pytest

from zendar_dataset.radar.cfar import cfar_2d, window_misfit


@pytest.mark.parametrize(("shape", "kwargs"), [
    ((16, 8), {}),  # the default window spans 13 Doppler cells
    ((10, 32), {}),  # and reaches 10 range cells each side
    ((3, 20, 13), {"edge": "wrap"}),  # wrapping range, the window spans 21 range cells
    ((32, 16), {"guard": (1, 4), "train": (1, 4)}),
])
def test_a_misfit_is_the_message_cfar_2d_raises(shape, kwargs):
    misfit = window_misfit(shape, **kwargs)
    assert misfit is not None and "the window spans" in misfit
    with pytest.raises(ValueError) as raised:
        cfar_2d(np.ones(shape), **kwargs)
    assert str(raised.value) == misfit


@pytest.mark.parametrize(("shape", "kwargs"), [((11, 13), {}), ((2, 64, 32), {}), ((21, 13), {"edge": "wrap"}),
                                               ((5, 5), {"guard": (0, 0), "train": (2, 2)})])
def test_a_window_that_fits_has_no_misfit(shape, kwargs):
    assert window_misfit(shape, **kwargs) is None
    assert cfar_2d(np.ones(shape), **kwargs).mask.shape == shape


def test_window_misfit_checks_its_arguments():
    with pytest.raises(ValueError, match="edge"):
        window_misfit((64, 32), edge="mirror-all")
    with pytest.raises(ValueError, match="R, D"):
        window_misfit((64,))
    with pytest.raises(ValueError, match="non-negative"):
        window_misfit((64, 32), guard=(-1, 1))
