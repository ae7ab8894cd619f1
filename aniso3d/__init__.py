"""aniso3d: render finely structured 3D objects fast and without aliasing, by
turning polygon meshes into an anisotropic 3D texture drawn as oriented point
splats (Ito, Fujimoto, Muraoka, Chiba).

The data flow, one module per stage: :mod:`aniso3d.build.mesh` (load) ->
:mod:`aniso3d.build.clip` (exact clipping into voxels) -> :mod:`aniso3d.build.texture`
(density and shading spheres) -> :mod:`aniso3d.build.points` (oriented points) ->
the renderers.
"""

from aniso3d.build import scenes
from aniso3d.build.mesh import Mesh, load_mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.texture import AnisoTexture, build_texture, sphere_directions
from aniso3d.errors import Aniso3DError, FormatError, InputError, ResourceError

__version__ = "0.1.0"

__all__ = [
    "Aniso3DError",
    "AnisoTexture",
    "FormatError",
    "InputError",
    "Mesh",
    "PointCloud",
    "ResourceError",
    "build_texture",
    "load_mesh",
    "scenes",
    "sphere_directions",
]
