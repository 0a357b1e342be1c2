"""Fixtures of the trainer tests."""

import pytest
from train_testing import tiny_data_factory


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory):
    """``env -> (expert file, pre file)``, generated once per session by abco_data."""
    return tiny_data_factory(tmp_path_factory.mktemp("tiny_data"))
