"""aniso3d: render finely structured 3D objects fast and without aliasing, by
turning polygon meshes into an anisotropic 3D texture drawn as oriented point
splats or by ray marching (Ito, Fujimoto, Muraoka, Chiba).

The data flow, one subpackage per stage:

- :mod:`aniso3d.build`: load a mesh (or a :class:`Scene` of many instances of
  a few meshes), clip it exactly into voxels, register the
  pieces on each voxel's density and shading spheres
  (:class:`AnisoTexture`), derive oriented points (:class:`PointCloud`) and the
  level-of-detail pyramid (CPU, NumPy);
- :mod:`aniso3d.rendering`: the GL context, camera, lighting and the three
  renderers (polygons, volume, splats) behind one :class:`Renderer`;
- :mod:`aniso3d.bench` and :mod:`aniso3d.app`: the measurements and the front
  ends (the ``aniso3d`` command and the viewer), imported only when used.

The names below are the public API; submodules stay importable.
"""

from aniso3d.build import scenes
from aniso3d.build.mesh import Mesh, load_mesh
from aniso3d.build.points import PointCloud
from aniso3d.build.pyramid import Pyramid, pyramid
from aniso3d.build.scene import Scene, load_scene
from aniso3d.build.texture import AnisoTexture, build_texture, sphere_directions
from aniso3d.errors import Aniso3DError, FormatError, InputError, InputWarning, ResourceError
from aniso3d.rendering.camera import Camera, turntable
from aniso3d.rendering.context import GLContext
from aniso3d.rendering.lighting import Lighting
from aniso3d.rendering.quick import framing_camera
from aniso3d.rendering.quick import render as render
from aniso3d.rendering.renderer import Renderer, render_frames
from aniso3d.rendering.video import write_video

__version__ = "0.1.0"

__all__ = [
    "Aniso3DError",
    "AnisoTexture",
    "Camera",
    "FormatError",
    "GLContext",
    "InputError",
    "InputWarning",
    "Lighting",
    "Mesh",
    "PointCloud",
    "Pyramid",
    "Renderer",
    "ResourceError",
    "Scene",
    "build_texture",
    "framing_camera",
    "load_mesh",
    "load_scene",
    "pyramid",
    "render",
    "render_frames",
    "scenes",
    "sphere_directions",
    "turntable",
    "write_video",
]
