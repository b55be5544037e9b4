"""The runnable examples in the methods' docstrings run and print what they claim."""
import doctest
import importlib

import pytest

MODULES = ["methods.bilateral", "methods.joint_bilateral", "methods.rolling_guidance", "methods.gaussian",
           "methods.tools.synthetic"]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
