"""Meshing: the Mesh type and marching cubes (mesh, marching), walls (walls, refine), files
(formats: the table; exchange: encode, save, load), and realise (a spec to its mesh in one call)."""
