"""The tissue of a run: which model cuts and relaxes (:func:`make_tissue`), and the cut tissue as a model (:func:`cut_model`).

Used by the offline run (:mod:`cutkit.simulate.run`), the session that
settles and holds the tissue (:mod:`cutkit.simulate.session`) and the
recorders that write the cut model (:mod:`cutkit.simulate.record`); it
imports none of them.
"""

from __future__ import annotations

from cutkit.tissue.physics import TissuePhysics

#: Most settle iterations of each material model by default: Newton steps of
#: the element model, which stops earlier at its residual (SimulateOptions.settle_rtol),
#: Gauss-Seidel sweeps of the springs.
SETTLE_MAX_SWEEPS = {"neohookean": 50, "springs": 100}


def make_tissue(model, store, material_model: str, opt) -> TissuePhysics:
    """The physics of a run over ``store`` (:class:`~cutkit.tissue.store.TissueStore`, or None: the
    model's own): :class:`ElasticTissue` or the paper's springs (:class:`Tissue`), a
    :class:`~cutkit.tissue.TissuePhysics`."""
    if material_model == "springs":
        from cutkit.relax.spring_tissue import Tissue

        return Tissue(model, store, dt0=opt.dt0, n_lists=opt.n_lists, tolerance_fraction=opt.tolerance_fraction,
                      volume_stiffness=opt.volume_stiffness)
    from cutkit.relax.elastic_tissue import DEFAULT_SOLVER, ElasticTissue

    rest = {} if opt.rest_rtol is None else {"rest_rtol": opt.rest_rtol}
    return ElasticTissue(model, store, step_s=1.0 / opt.geometry_rate_hz, **rest,
                         solver=opt.solver or ("newton" if opt.element == "anp" else DEFAULT_SOLVER),
                         element=opt.element, deviatoric_smoothing=opt.deviatoric_smoothing)




def cut_model(cm, tis, model, summary: dict | None = None):
    """The cut tissue (cut mesh ``cm``, physics ``tis``) as a model: rest configuration, cut topology, displacement as point data.

    A model is defined in its rest configuration (the springs' rest lengths
    follow from it), so ``points`` are the rest positions of the cut mesh,
    where every tetrahedron is positively oriented; ``point_data
    ["displacement"]`` (mm) holds the relaxed deformation (ParaView: Warp By
    Vector).  Nodes no tetrahedron uses are dropped (``to_model`` compacts
    the numbering and carries the boundary conditions over to it).
    """
    import dataclasses

    from cutkit.cutting import to_model

    m = to_model(cm, model, points=cm.points, point_data={"displacement": tis.displacement})
    provenance = dict(m.provenance)
    stages = dict(provenance.get("stages", {}))
    if summary is not None:
        stages["simulate"] = {"options": summary.get("options"), "cut_tets": summary.get("cut_tets"),
                              "simulated_s": summary.get("simulated_s")}
    provenance["stages"] = stages
    return dataclasses.replace(m, provenance=provenance)
