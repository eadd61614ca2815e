"""Static equilibrium of the element model by either solver: projected Newton or the sweeps.

One entry point above both solvers (:mod:`cutkit.relax.newton` builds on
:mod:`cutkit.relax.vbd`, so the choice between them lives here).
"""

from __future__ import annotations

from cutkit.errors import InputError
from cutkit.relax.anp import check_element
from cutkit.relax.elastic import ElementModel
from cutkit.relax.newton import newton_static
from cutkit.relax.vbd import SolveInfo, vbd_static


def static_solve(em: ElementModel, positions, f_ext=None, gravity=None, *, solver: str = "newton",
                 element: str | None = None, **tolerances) -> SolveInfo:
    """Relax ``positions`` (n, 3) float64 (in place) to static equilibrium under the external forces.

    ``solver="newton"`` (the default) solves by projected Newton
    (:func:`cutkit.relax.newton.newton_static`; ``iterations`` counts Newton
    iterations), which converges slender bodies in a few dozen iterations;
    ``"vbd"`` by the sweeps of :func:`cutkit.relax.vbd.iterate` (``chebyshev`` only there).
    ``tolerances``: ``rtol``, ``atol``, ``max_iterations``.  ``element``
    (``"nh"`` or ``"anp"``) sets ``em.element`` for this solve and the ones
    after it (None: the model's own); the average nodal pressure tetrahedron
    is solved by Newton only.
    """
    chosen = em.element if element is None else check_element(element)
    if solver == "vbd" and chosen != "nh":
        raise InputError(f"element {chosen!r} is solved by solver='newton' only")
    em.element = chosen
    if solver == "newton":
        if "chebyshev" in tolerances:
            raise InputError("chebyshev acceleration belongs to solver='vbd'")
        return newton_static(em, positions, f_ext, gravity, **tolerances)
    if solver != "vbd":
        raise InputError(f"solver must be newton or vbd, not {solver!r}")
    return vbd_static(em, positions, f_ext, gravity, **tolerances)
