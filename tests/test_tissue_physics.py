"""Both tissue models provide what the session asks of a physics (cutkit.tissue.TissuePhysics)."""

import inspect

import pytest

from cutkit.tissue import TissuePhysics


def _members():
    return [n for n in dir(TissuePhysics) if not n.startswith("_") and n not in dir(object)]


@pytest.mark.parametrize("module, name", [("cutkit.simulate.tissue", "Tissue"),
                                          ("cutkit.simulate.elastic_tissue", "ElasticTissue")])
def test_tissue_models_implement_the_protocol(module, name):
    import importlib

    cls = getattr(importlib.import_module(module), name)
    members = _members()
    assert {"settle", "advance", "apply_delta", "rebase", "load_shares", "masses", "positions"} <= set(members)
    for m in members:
        assert hasattr(cls, m), f"{name} has no {m}"
        want = getattr(TissuePhysics, m)
        if inspect.isfunction(want):  # same number of positional parameters
            got = getattr(cls, m)
            n_want = len(inspect.signature(want).parameters)
            params = inspect.signature(got).parameters.values()
            required = sum(p.default is inspect.Parameter.empty for p in params)
            assert required <= n_want <= len(params), f"{name}.{m}"
