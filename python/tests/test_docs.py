"""What `help()` shows: every class documents its constructor's arguments."""

import inspect

import pytest

import hexmss

CLASSES = [
    hexmss.Mesh,
    hexmss.Material,
    hexmss.Model,
    hexmss.Problem,
    hexmss.PlaneModel,
    hexmss.PlaneProblem,
    hexmss.State,
    hexmss.Integrator,
    hexmss.Simulation,
]


@pytest.mark.parametrize("cls", CLASSES, ids=lambda c: c.__name__)
def test_class_docs_name_every_constructor_argument(cls):
    doc = cls.__doc__ or ""
    params = inspect.signature(cls).parameters
    assert params, cls
    for name, param in params.items():
        assert name in doc, f"{cls.__name__}: {name} is not described"
        if param.default is not inspect.Parameter.empty:
            # The default is stated where the argument is shown.
            assert f"{name}={param.default!r}" in doc or f"{name}=" in doc, (
                f"{cls.__name__}: the default of {name} is not stated"
            )


def test_the_model_says_what_no_parameterization_means():
    assert "volumetric-barrier+hg" in hexmss.Model.__doc__
