"""Maps: occupancy grid (ROS map_server YAML + PGM) and elevation model (ESRI ASCII grid)."""

from .dem import load_dem, write_dem
from .grid import ElevationModel, OccupancyGrid
from .ogm import load_ogm, write_pgm

__all__ = ["OccupancyGrid", "ElevationModel", "load_ogm", "load_dem", "write_pgm", "write_dem"]
