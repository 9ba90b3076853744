"""ALE mesh motion: surface relocation and respacing, interior smoothing, remapping, velocities."""

from ntncontact.ale.remap import (
    PointLocation,
    Remapper,
    conservative_velocity_correction,
    momenta,
    remap_fields,
)
from ntncontact.ale.smoothing import (
    Smoother,
    SmoothingResult,
    boundary_node_mask,
    nodes_within_layers,
)
from ntncontact.ale.surface import (
    SurfaceCurve,
    point_at,
    respace_surface,
)
from ntncontact.ale.velocity import convective_velocity, mesh_velocity

__all__ = [
    "PointLocation",
    "Remapper",
    "Smoother",
    "SmoothingResult",
    "SurfaceCurve",
    "boundary_node_mask",
    "conservative_velocity_correction",
    "convective_velocity",
    "mesh_velocity",
    "momenta",
    "nodes_within_layers",
    "point_at",
    "remap_fields",
    "respace_surface",
]
