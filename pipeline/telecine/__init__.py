"""Telecine and deliverables: pulldown to interlaced fields, inverse telecine, movies, contact sheets.

Modules: `fields` (field model), `cadence` (pulldown plans and rates), `inverse`
(detection and recovery), `sequence` (EXR sequence discovery and validation), `convert`
(EXR -> EXR), `movie` (PyAV encoding), `contact_sheet`, `reference` (FFmpeg's filter),
`deliver` (what `motion render --deliver` runs). Heavy libraries (av, matplotlib) are
imported only when a movie or a sheet is made.
"""

from .convert import inverse_sequence, telecine_sequence
from ..deliverables import FORMATS, parse_formats
from .deliver import deliver

__all__ = ["FORMATS", "deliver", "inverse_sequence", "parse_formats", "telecine_sequence"]
