"""The average nodal pressure (ANP) tetrahedron: linear tets that do not lock near incompressibility.

Linear tetrahedra with a volumetric energy per element lock as nu -> 1/2:
each element must keep its own volume, and a mesh of them has too few
motions that do (docs/relaxation.md, "Element choice").  The ANP tetrahedron
(Bonet & Burton 1998; Bonet, Marriott & Hassan 2001; Joldes, Wittek & Miller
2009) keeps the deviatoric energy per element and moves the volumetric
energy to the nodes, where it depends on the nodal volume ratio

    J_a = (sum of current tet volumes around a / 4) / (the same at rest),

one constraint per node instead of one per element (about five times fewer).
Nodes held in all three directions carry none: their elements' volume goes to
the free corners (:func:`pressure_shares`), else the constraints of a bonded
face lock the block near it (docs/relaxation.md).
The energy, its split and its derivatives are in :mod:`cutkit.relax._anp_kernels`.

That removes the volumetric locking but leaves the linear tet's stiffness in
bending (its shear locking, there at nu 0.3 too).  With ``deviatoric_smoothing``
alpha > 0 (``build_element_model``) a share alpha of the deviatoric energy is
carried by each node's smoothed deformation gradient instead (the alpha-FEM of
Liu, Nguyen-Thoi & Lam 2008; the selective node-based smoothed FEM of
Nguyen-Thoi, Liu et al. 2009): node-based smoothing is as soft as linear tets
are stiff, and :data:`ANP_SMOOTHING` is the measured blend.

Where materials meet, each keeps its own nodal volume ratio and pressure
(:func:`material_patches`).
Everything the nodes need is derived from the element list each time it is
asked for (:func:`nodal_terms`), so after a cut the duplicated nodes have
the nodal volumes of the tets that hold them, and the natural (prestrained)
rest shapes of :func:`cutkit.relax.elastic.rest_shape` are the rest shapes.
Only the projected Newton solver (:mod:`cutkit.relax.newton`) minimises it;
vertex block descent's exact vertex quadratic does not hold for it.
"""

from __future__ import annotations

import hashlib
import weakref

import numpy as np

from cutkit.errors import InputError
from cutkit.relax import _anp_kernels as KP
from cutkit.relax import _elastic_kernels as KE
from cutkit.relax import _newton_kernels as KN
from cutkit.relax.vbd import NEVER_STOP

#: The element choices of the element model: ``"nh"`` stable neo-Hookean linear tets (one
#: volumetric energy per element), ``"anp"`` the average nodal pressure tetrahedron.
ELEMENTS = ("nh", "anp")

#: The share alpha of the deviatoric energy on the nodes (``deviatoric_smoothing``) that meets
#: 5 % of a refined P2 reference on the cantilever and the bonded block at nu 0.3-0.49 on the
#: once-refined meshes (docs/relaxation.md; benchmarks/anp_deviatoric_blend.py scans alpha,
#: benchmarks/element_locking.py --smoothing measures it).
ANP_SMOOTHING = 0.7


def check_element(element: str) -> str:
    """``element`` if it is one of :data:`ELEMENTS`, else an :class:`InputError`."""
    if element not in ELEMENTS:
        raise InputError(f"element must be one of {', '.join(ELEMENTS)}, not {element!r}")
    return element


def active_elements(em) -> KE.Elements:
    """The model's elements in use (``n_elements`` rows), contiguous."""
    m = em.n_elements
    return KE.Elements(*(np.ascontiguousarray(a[:m]) for a in (em.tets, em.Dminv, em.volume, em.mu, em.lam)))


def nodal_terms(em, el: KE.Elements | None = None) -> KP.NodalTerms:
    """Volumes, bulk and shear weights and tets of every node's patches, from the active elements.

    A node's patch is the tets around it of one material (equal ``mu`` and ``lam``): where
    materials meet a node has one patch, one nodal volume ratio and one pressure, per material
    (:func:`material_patches`).

    Parameters
    ----------
    em : ElementModel
    el : Elements, optional
        Its active elements (default :func:`active_elements`).

    Returns
    -------
    NodalTerms
        Per patch (P,) with P >= n (patch a < n is node a's first material's): ``volume`` mm^3
        = sum V_e / 4, ``bulk`` N mm = sum share V_e K_e with K = lam + 2 mu / 3, the patch-to-tet
        lists of the active tets, ``shear`` N mm = sum V_e mu_e / 4, ``pressure_volume`` mm^3 =
        sum share V_e; ``smoothing`` = ``em.deviatoric_smoothing``, ``share`` (m, 4)
        (:func:`pressure_shares`), ``patch`` (m, 4) int64, the patch of each corner, and the
        patches' members and the node rows that gather them (``_anp_kernels.patch_members``).
    """
    el = active_elements(em) if el is None else el
    n = em.n_nodes
    live = np.flatnonzero(el.volume > 0.0)
    patch, count = material_patches(el.tets, el.volume, el.mu, el.lam, n)
    corners = patch[live].ravel()
    ptr, node_tets, node_corner = KP.patch_tets(patch, live, count)
    quarter = np.repeat(0.25 * el.volume[live], 4)
    share = pressure_shares(el.tets, el.volume, np.asarray(em.fixed, bool).reshape(n, -1).all(axis=1))
    shared = share[live].ravel() * np.repeat(el.volume[live], 4)
    bulk = np.repeat(el.lam[live] + 2.0 * el.mu[live] / 3.0, 4)
    shear = np.repeat(el.mu[live], 4)
    return KP.NodalTerms(np.bincount(corners, quarter, minlength=count),
                         np.bincount(corners, shared * bulk, minlength=count), ptr, node_tets, node_corner,
                         np.bincount(corners, quarter * shear, minlength=count), float(em.deviatoric_smoothing),
                         share, np.bincount(corners, shared, minlength=count), patch,
                         *KP.patch_members(np.ascontiguousarray(el.tets, np.int64), ptr, node_tets, n))


#: The last model's nodal terms: (weak reference to the model, digest of what they are made of,
#: the terms).  One entry: a run has one element model; replaced as a whole, so a reader in another
#: thread sees an old or a new entry, never a mix.
_last_terms: tuple = (None, b"", None)


def cached_nodal_terms(em, el: KE.Elements) -> KP.NodalTerms:
    """:func:`nodal_terms` of ``em``'s active elements ``el``, kept while what they are made of stays.

    The terms depend on the element set only (corners, rest volumes, Lame parameters, held nodes,
    the smoothing share), not on positions, yet every force, energy and Hessian evaluation needs
    them (on the demo knee about 0.08 s to sum, and an ANP incision makes about 250 evaluations).
    The key is a digest of exactly those inputs (blake2b, about 10 ms on the knee), so any change
    to them, in place or not, computes them again.
    """
    global _last_terms
    held = np.asarray(em.fixed, bool).reshape(em.n_nodes, -1).all(axis=1)
    digest = hashlib.blake2b(digest_size=16)
    for a in (el.tets, el.volume, el.mu, el.lam, held,
              np.array([em.n_nodes, em.deviatoric_smoothing], np.float64)):
        digest.update(np.ascontiguousarray(a).data)
    key = digest.digest()
    ref, last_key, terms = _last_terms
    if ref is not None and ref() is em and last_key == key:
        return terms
    terms = nodal_terms(em, el)
    _last_terms = (weakref.ref(em), key, terms)
    return terms


def material_patches(tets, volume, mu, lam, n: int) -> tuple[np.ndarray, int]:
    """The patch of every element corner: its node and its element's material (``mu``, ``lam``).

    Averaging the volume (and the smoothed deformation) over every tet around a node ties the
    materials that meet there: on the demo knee, bone (E 17 GPa) and fat (3 kPa) share nodes,
    and one nodal pressure for both gives the fat tets the bone's bulk weight; a static Newton
    solve of the cut knee then did not converge in 100 iterations (residual 6,600 N against a
    force scale of 28 N), where with the bone at 1 MPa it took 3 (benchmarks/anp_knee.py).  The
    pressure is discontinuous across a material interface, so each material keeps its own patch.

    Parameters
    ----------
    tets : (m, 4) int64
    volume : (m,) float64
        0: inactive (its corners get their node's patch; they count nowhere).
    mu, lam : (m,) float64
    n : int
        Nodes.

    Returns
    -------
    patch : (m, 4) int64
        Node a's patch of its material with the smallest (mu, lam) is a; further materials at a
        node get patches n, n + 1, ... in the order of (node, material).
    count : int
        Patches, >= n.
    """
    tets = np.ascontiguousarray(tets, np.int64)
    live = np.flatnonzero(np.asarray(volume) > 0.0)
    if live.size == 0:
        return tets.copy(), n
    _, in_mu = np.unique(np.asarray(mu)[live], return_inverse=True)  # (mu, lam) in lexicographic order
    lams, in_lam = np.unique(np.asarray(lam)[live], return_inverse=True)
    _, material = np.unique(in_mu.ravel() * lams.size + in_lam.ravel(), return_inverse=True)
    patch, count = KP.corner_patches(tets, live, np.ascontiguousarray(material.ravel(), np.int64), int(n))
    return patch, int(count)


def pressure_shares(tets, volume, held) -> np.ndarray:
    """The share of each element's volume that each corner's nodal volume takes (volumetric term).

    A node whose displacement is prescribed (held in all three directions) carries no volume
    constraint: each element's volume goes to its free corners in equal parts, 1/4 each where
    none is held.  A held node's nodal volume constraint would add a constraint on the free
    nodes' motion without adding an equation, lowering the constraint ratio (equations per
    volume constraint; Hughes, *The Finite Element Method*, 1987, sec. 4.3) on the held faces,
    where the bonded block locks (docs/relaxation.md, "Element choice").

    Parameters
    ----------
    tets : (m, 4) int64
    volume : (m,) float64
        0: inactive (share 0).
    held : (n,) bool
        Nodes held in all three directions.

    Returns
    -------
    (m, 4) float64
        Rows sum to 1 for active elements with a free corner, else 0.
    """
    free = ~np.asarray(held, bool)[np.asarray(tets, np.int64)]
    count = free.sum(axis=1)
    share = np.where(free, 1.0 / np.maximum(count, 1)[:, None], 0.0)
    share[np.asarray(volume) <= 0.0] = 0.0
    return np.ascontiguousarray(share)


def anp_energy(em, positions) -> float:
    """Total stored energy of the ANP model, N mm."""
    el = active_elements(em)
    return float(KP.energy(_positions(em, positions), el, cached_nodal_terms(em, el)))


def anp_forces(em, positions) -> np.ndarray:
    """Elastic node forces -dW/dx of the ANP model, N: (n, 3) float64."""
    el = active_elements(em)
    out = np.zeros((em.n_nodes, 3))
    KP.forces(_positions(em, positions), el, cached_nodal_terms(em, el), out)
    return out


def patch_neighbours(tets, volume, n: int):
    """Node rows of the ANP Hessian's pattern: every pair of nodes in one node's patch.

    Parameters
    ----------
    tets : (m, 4) int64
    volume : (m,) float64
        0: inactive.
    n : int

    Returns
    -------
    node_ptr : (n + 1,) int64
    node_idx : (nb,) int64
        Sorted columns; every node has its diagonal block.
    """
    import scipy.sparse as sp

    live = np.flatnonzero(np.asarray(volume) > 0.0)
    corners = np.asarray(tets, np.int64)[live].ravel()
    T = sp.csr_matrix((np.ones(corners.size), (corners, np.repeat(np.arange(live.size), 4))), shape=(n, live.size))
    ring = (T @ T.T).tocsr()
    wide = (ring @ ring + sp.identity(n, format="csr")).tocsr()
    wide.sort_indices()
    return wide.indptr.astype(np.int64), wide.indices.astype(np.int64)


def anp_pattern(em, el: KE.Elements | None = None) -> KN.Pattern:
    """The sparsity pattern of the ANP Hessian, in :mod:`cutkit.relax._newton_kernels`'s layout."""
    el = active_elements(em) if el is None else el
    ptr, idx = patch_neighbours(el.tets, el.volume, em.n_nodes)
    blocks, _ = KN.element_blocks(el.tets, el.volume, ptr, idx, NEVER_STOP)
    indptr, indices, diagonal = KN.scalar_pattern(ptr, idx)
    return KN.Pattern(ptr, idx, blocks, indptr, indices, diagonal)


def assemble_anp_hessian(em, positions, pattern: KN.Pattern, project: int, data: np.ndarray) -> None:
    """The ANP Hessian into the CSR values ``data`` (9 nb,) float64 of ``pattern`` (:func:`anp_pattern`).

    ``project`` 0: exact; 1: each element's 9x9 stress Hessian projected to positive
    semi-definite (the nodal terms are as they stand, positive semi-definite).
    """
    el = active_elements(em)
    KP.assemble_hessian(_positions(em, positions), el, cached_nodal_terms(em, el), pattern, int(project), data)


def anp_hessian(em, positions, project: int = 0):
    """The ANP Hessian d2W/dx2 as a (3n, 3n) scipy CSR matrix (no constraints)."""
    import scipy.sparse as sp

    pat = anp_pattern(em)
    data = np.empty(pat.indices.shape[0])
    assemble_anp_hessian(em, positions, pat, project, data)
    n3 = 3 * em.n_nodes
    return sp.csr_matrix((data, pat.indices, pat.indptr), shape=(n3, n3))


def _positions(em, positions) -> np.ndarray:
    x = np.ascontiguousarray(positions, np.float64)
    if x.shape != (em.n_nodes, 3):
        raise InputError(f"positions must have shape ({em.n_nodes}, 3), got {x.shape}")
    return x


def element_forces(em, positions) -> np.ndarray:
    """Elastic node forces -dW/dx of the model's element (``em.element``), N: (n, 3) float64."""
    if em.element == "anp":
        return anp_forces(em, positions)
    from cutkit.relax.vbd import elastic_forces

    return elastic_forces(em, positions)
