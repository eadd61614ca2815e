"""Relaxation of the tissue: a mass-spring model and its semi-implicit, adaptive integration (paper section 5)."""

from cutkit.relax.model import (
    Control,
    SpringModel,
    SpringState,
    build_spring_model,
    initial_state,
)
from cutkit.relax.integrate import kinetic_energy, spring_energy, spring_forces, step, total_momentum
from cutkit.relax.topology import add_nodes, add_springs, remove_springs
from cutkit.relax.adaptive import NodeLists

__all__ = [
    "Control",
    "SpringModel",
    "SpringState",
    "build_spring_model",
    "initial_state",
    "step",
    "spring_forces",
    "spring_energy",
    "kinetic_energy",
    "total_momentum",
    "add_nodes",
    "add_springs",
    "remove_springs",
    "NodeLists",
]
