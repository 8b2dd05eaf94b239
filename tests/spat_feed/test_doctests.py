"""Run the spat_feed docstring examples (the default test paths collect doctests only from advisory/)."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "timing.plans",
    "timing.timemark",
    "timing.messages",
    "timing.paper",
    "timing.signal_plans",
    "road.corridors",
    "transport.store",
    "transport.client",
    "transport.mqtt",
    "transport.broker",
    "prediction.predictor",
    "prediction.observe",
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(f"spat_feed.{name}")
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.failed == 0
