"""The sparsity pattern of an element model's Newton matrix, carried over the model's cuts.

Built once in full (:func:`cutkit.relax._newton_kernels.node_neighbours`,
``element_blocks``, ``scalar_pattern``), then, after each topology change,
updated where the change was (:mod:`cutkit.relax._pattern_kernels`): the
same arrays as a full build.  On the demo knee after the shipped incision
(1,338 of 30,608 nodes touched) an update takes 32-38 ms against 137-152
ms for a full build on one core (``NUMBA_NUM_THREADS=1 python
benchmarks/newton_pattern.py --json --knee knee.h5``).  The first resting
step after a stroke needs the pattern of the cut mesh, so this is on the
path from the hand stopping to the tissue at rest.
"""

from __future__ import annotations

import numpy as np

from cutkit.relax import _newton_kernels as KN
from cutkit.relax import _pattern_kernels as KP
from cutkit.relax.vbd import NEVER_STOP

#: Past this fraction of the nodes touched the pattern is built in full: an update's work grows
#: with the rows it builds again, a full build's does not.
FULL_BUILD_FRACTION = 0.25


class HessianPattern:
    """The :class:`~cutkit.relax._newton_kernels.Pattern` of ``em``'s Newton matrix (nodes and
    active elements as they are when :meth:`get` is called), kept between calls.

    One object may serve several solvers of the same model (a tissue's Newton solver and its
    resting steps' solver share one).  The neo-Hookean and linear elements only: the ANP element's stencil
    reaches a node's patch (:func:`cutkit.relax.anp.anp_pattern`), which a solver builds itself.

    Attributes
    ----------
    builds, updates : int
        Full builds, and updates of a kept pattern, made so far.
    elements_changed, rows_rebuilt : int
        Of the last update: the elements switched on, off or rewritten since the pattern before,
        and the node rows built again (the others were moved).
    """

    def __init__(self, em):
        self.em = em
        self.builds = 0
        self.updates = 0
        self.elements_changed = 0
        self.rows_rebuilt = 0
        self._pattern = None
        self._tets = None  # (m, 4) int64: the elements' corners when the pattern was made
        self._active = None  # (m,) bool
        self._n = 0
        self._checked = False  # no topology change since the pattern was made or checked

    def changed(self) -> None:
        """The model's nodes or elements have changed (a cut): the next :meth:`get` looks again."""
        self._checked = False

    def get(self, halt=None) -> KN.Pattern | None:
        """The pattern now; None where ``halt`` ((1,) int64, optional: a waiting cut) stopped its
        build (what was kept stays, for the next call)."""
        em = self.em
        n, m = em.n_nodes, em.n_elements
        if self._pattern is not None and self._checked and (n, m) == (self._n, self._tets.shape[0]):
            return self._pattern
        flag = NEVER_STOP if halt is None else halt
        tets, volume = em.tets[:m], em.volume[:m]
        if self._pattern is None or n < self._n or m < self._tets.shape[0]:
            pattern = self._build(tets, volume, n, flag)
        else:
            pattern = self._update(tets, volume, n, flag)
        if pattern is None:
            return None
        if pattern is not self._pattern:
            self._pattern, self._n = pattern, n
            self._tets, self._active = tets.copy(), volume > 0.0
        self._checked = True
        return self._pattern

    def _build(self, tets, volume, n: int, flag):
        ptr, idx, whole = KN.node_neighbours(tets, volume, n, flag)
        if not whole:
            return None
        blocks, whole = KN.element_blocks(tets, volume, ptr, idx, flag)
        if not whole:
            return None
        self.builds += 1
        return KN.Pattern(ptr, idx, blocks, *KN.scalar_pattern(ptr, idx))

    def _update(self, tets, volume, n: int, flag):
        old = self._pattern
        touched, changed, whole = KP.touched_nodes(tets, volume, self._tets, self._active, self._n, n, flag)
        if not whole:
            return None
        if changed == 0 and n == self._n and tets.shape[0] == self._tets.shape[0]:
            return old  # the same elements on the same nodes
        if np.count_nonzero(touched) > FULL_BUILD_FRACTION * n:
            return self._build(tets, volume, n, flag)
        ptr, idx, whole = KP.update_node_rows(tets, volume, touched, old.node_ptr, old.node_idx, flag)
        if not whole:
            return None
        blocks, whole = KP.update_element_blocks(tets, volume, touched, ptr, idx, old.node_ptr,
                                                 old.element_blocks, flag)
        if not whole:
            return None
        self.updates += 1
        self.elements_changed, self.rows_rebuilt = int(changed), int(np.count_nonzero(touched))
        return KN.Pattern(ptr, idx, blocks, *KN.scalar_pattern(ptr, idx))
