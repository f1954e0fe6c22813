"""Small synthetic targets written as real mesh files (shared by conftest and tests)."""

from __future__ import annotations

import numpy as np
import trimesh


def write_plates(path, plates):
    """Write square plates facing -z (towards a lidar looking along +z) as one OBJ.

    plates : list of (size_m, z_offset_m, tilt_deg about the y axis)
    """
    meshes = []
    for size, z, tilt in plates:
        box = trimesh.creation.box(extents=(size, size, 1e-3))
        box.apply_transform(trimesh.transformations.rotation_matrix(np.radians(tilt), (0, 1, 0)))
        box.apply_translation((0, 0, z))
        meshes.append(box)
    trimesh.util.concatenate(meshes).export(path)
    return str(path)
