"""Voxel grids and participating media (design.md §6).

* :class:`VoxelGrid` -- occupancy, solid colour, smoke colour and density on a regular grid,
  with GO-Draaw's editing operations (quirks fixed), picking, ``.npz`` / ``.vol`` files.
* :mod:`.voxelize` -- mesh voxelisation (surface / solid); :mod:`.pick` -- exact DDA.
"""
from __future__ import annotations

from .volfile import read_vol, write_vol
from .voxel_grid import VoxelGrid

__all__ = ["VoxelGrid", "read_vol", "write_vol"]
