"""Dynamics stage: simulate rigid bodies, particle systems, flocks and planned-path
followers, and sample them at any time (docs/dynamics.md). world.py builds the world from
the scene, step.py runs the step stages, track.py records, simulation.py is the result."""

from .particles import ParticleSamples
from .simulation import Simulation, simulate

__all__ = ["ParticleSamples", "Simulation", "simulate"]
