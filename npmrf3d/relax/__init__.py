"""Relaxation algorithms: one module each (``icm``; annealing comes next)."""

from .icm import relax_icm

RELAXATIONS = {"icm": relax_icm}

__all__ = ["RELAXATIONS", "relax_icm"]
