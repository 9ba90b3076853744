"""ntncontact: 2D finite-deformation contact and impact with the node-to-node ALE method."""

__version__ = "0.1.0"
