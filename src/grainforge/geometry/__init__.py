"""Geometry kernels on triangle meshes: solids, spheres, rotations, voxels, harmonics."""
