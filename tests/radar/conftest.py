import pytest
from tests.radar.radar_helpers import ula_params

from zendar_dataset.radar.fmcw import FmcwParams


@pytest.fixture
def params() -> FmcwParams:
    return ula_params()
