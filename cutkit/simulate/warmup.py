"""Compile (and cache) the run side's numba kernels by cutting a tiny model.

A live session runs :func:`warm_up` in process before its clock starts, so
that no kernel is first loaded (10-30 ms each) in the middle of a cut;
``cutkit demo`` runs it beside the build (:mod:`cutkit.demo.warmup`).
"""

from __future__ import annotations

import tempfile

import numpy as np

#: The two tissues of the warm-up slab: a stiff layer over a soft one, with the scalpel's default
#: cut parameters (any finite values compile the same kernels; these make the blade cut both).
WARM_UP_TISSUES = ((1, "skin", 150e3), (3, "muscle", 30e3))


def warm_up_model(fixed_ends: bool = True):
    """The warm-up slab: 16 x 8 x 12 mm, a 2 mm skin layer over prestressed muscle (a TetModel)."""
    from cutkit.mesh.generate import box_mesh
    from cutkit.model.tetmodel import MATERIAL_FIELDS, BoundaryConditions, Materials, Prestress, TetModel
    from cutkit.scalpel.model import DEFAULT_MATERIAL

    points, tets = box_mesh((8, 4, 6), spacing=(2.0, 2.0, 2.0))
    centre = points[tets].mean(axis=1)
    labels = np.where(centre[:, 1] < 2.0, 1, 3).astype(np.int32)
    rows = []
    for label, name, E in WARM_UP_TISSUES:
        row = {k: 0.0 for k in MATERIAL_FIELDS}
        row.update(DEFAULT_MATERIAL)
        row.update(E=E, poisson_ratio=0.45, density=1100.0, damping=8.0)
        rows.append(dict(label=label, name=name, **row))
    ends = np.flatnonzero((points[:, 2] == 0) | (points[:, 2] == 12.0)) if fixed_ends else np.zeros(0, np.int64)
    return TetModel.from_arrays(points, tets, labels, materials=Materials.from_rows(rows),
                                boundary=BoundaryConditions(fixed_nodes=ends),
                                prestress=Prestress(label=np.array([3], np.int32),
                                                    fibre_direction=np.array([[0.0, 0.0, 1.0]]),
                                                    prestrain=np.array([0.08])))


def warm_up(outputs: bool = True, material_model: str | None = None, extras: bool = True) -> None:
    """Cut the warm-up slab (:func:`warm_up_model`) along a short incision; nothing is kept.

    Parameters
    ----------
    outputs : bool
        Also write frames and the cut model (their kernels).
    material_model : str, optional
        The tissue model to cut (``SimulateOptions.material_model``); default the model's.
    extras : bool
        Also :func:`warm_up_extras`: the kernels a large model's run calls that the short cut misses.
    """
    from cutkit.cutting.trajectory import straight_incision
    from cutkit.simulate import SimulateOptions, simulate

    traj = straight_incision([4.0, 0.0, 6.3], [12.0, 0.0, 6.3], inward=[0, 1, 0], depth=3.0, approach=2.0,
                             press_time=0.2, cut_time=0.3, rate=100)
    with tempfile.TemporaryDirectory() as d:
        simulate(warm_up_model(), traj, d, SimulateOptions(frames=outputs, fps=2, write_model=outputs, hold_s=0.05,
                                                           settle_iterations=2, material_model=material_model))
    if extras:
        warm_up_extras()


def warm_up_extras() -> None:
    """The kernels a large model's run calls that :func:`warm_up`'s short cut misses: the resting
    steps' conjugate gradients (:func:`warm_up_conjugate_gradients`) and those of
    :func:`warm_up_missed_kernels`.  The short cut compiles hardly any of them (it shares the
    element model's), so a second process can compile these beside it (``cutkit demo``)."""
    warm_up_conjugate_gradients()
    warm_up_missed_kernels()


def warm_up_missed_kernels() -> None:
    """The kernels a stroke calls that the warm-up's short cut misses: the T-cone of a tet the tip
    has left (:func:`~cutkit.cutting.resubdivision.load_cone_kernel`), the fairing's search
    (:func:`~cutkit.cutting.fairing.load_fair_kernels`), the vertex smoothing's search
    (:func:`~cutkit.cutting.smoothing.load_smooth_kernels`), the swept blade's
    triangle against the surface hierarchy (an entry edge first), the blade's entry test
    (every pose of a blade outside the tissue) and the update of the Newton
    matrix's pattern after a stroke (the short cut rebases before any resting step); 10-30 ms each
    at a first call."""
    from cutkit.collision import SurfaceBVH, blade_entry, query_triangle
    from cutkit.cutting.fairing import load_fair_kernels
    from cutkit.cutting.resubdivision import load_cone_kernel
    from cutkit.cutting.smoothing import load_smooth_kernels

    load_cone_kernel()
    load_fair_kernels()
    load_smooth_kernels()
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    bvh = SurfaceBVH.build(points, np.array([[0, 1, 2]], np.int64))
    query_triangle(bvh, points, np.array([[0.2, 0.2, -1.0], [0.2, 0.2, 1.0], [0.3, 0.3, 1.0]]))
    blade_entry(bvh, points, points[0] + 1.0, points[0] + 2.0, points[0] + 1.5, points[0] + 2.5)
    warm_up_pattern_update()


def warm_up_pattern_update() -> int:
    """Build the warm-up slab's Newton pattern, take one element out and update it
    (:class:`~cutkit.relax.hessian_pattern.HessianPattern`); returns the updates made (1)."""
    from cutkit.relax.elastic import build_element_model
    from cutkit.relax.hessian_pattern import HessianPattern

    em = build_element_model(warm_up_model())
    pattern = HessianPattern(em)
    pattern.get()
    em.remove_elements(np.array([0], np.int64))
    pattern.changed()
    pattern.get()
    return pattern.updates


def warm_up_conjugate_gradients() -> int:
    """One static Newton iteration of the warm-up slab by conjugate gradients: a large model's resting
    steps solve by them (``newton.CHOLESKY_MAX_DOFS``), which the small slab's factorisations skip.
    Returns the conjugate-gradient iterations made."""
    from cutkit.relax.elastic import build_element_model
    from cutkit.relax.newton import NewtonSolver, newton_static

    model = warm_up_model()
    em = build_element_model(model)
    solver = NewtonSolver(em, linear="cg", hessian="projected")
    newton_static(em, model.points.copy(), max_iterations=1, solver=solver)
    return int(solver.counts["cg_iterations"])
