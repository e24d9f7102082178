"""Dynamics stage: simulate rigid bodies and particle systems, sample them at any time
(docs/dynamics.md)."""

from .particles import ParticleSamples
from .simulation import Simulation, simulate

__all__ = ["ParticleSamples", "Simulation", "simulate"]
