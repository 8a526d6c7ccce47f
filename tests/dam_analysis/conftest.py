"""Fixtures of the lift-analysis unit tests: the default configuration and one analyzer."""

from __future__ import annotations

import pytest

from dam_analysis.analysis import LiftAnalyzer
from dam_common.config import load_config


@pytest.fixture(scope='session')
def config():
    return load_config()


@pytest.fixture(scope='session')
def analyzer(config):
    return LiftAnalyzer(config)
